"""``colonbench evaluate``, ``leaderboard`` and ``methods``: methods run over a dataset, tables from stored runs."""

from __future__ import annotations

import sys
import time

from colonbench.commands import benchmark as benchmark_verbs
from colonbench.commands.common import add_model_args, add_suite_check_args, finite, floats, method_list, positive
from colonbench.errors import ColonbenchError, InputError
from colonbench.mapping import CONTEXT_MM, SEGMENT_MM


def cmd_evaluate(args):
    """Evaluate methods on a dataset's test shards into a run folder (resumable)."""
    from colonbench.benchmark.colon_evaluate import dataset_task
    from colonbench.benchmark.evaluate import evaluate, load_results
    from colonbench.benchmark.summary import summarize
    from colonbench.pipeline import with_sample

    made_for = dataset_task(args.data)
    task = args.task or made_for
    if task != made_for:
        raise ColonbenchError(f"{args.data} is a {made_for} dataset; --task {task} needs a "
                              f"{'task: colon' if task == 'colon' else 'segment'} manifest's data")
    if task == "colon":
        if args.track != "points":
            raise ColonbenchError("--track length is for segment data: a whole-colon map cuts the segments and knows "
                                  "their planes itself")
        return _evaluate_colons(args)
    if args.context_model:
        raise ColonbenchError("--context-model is for whole-colon maps (--task colon), where segments have planes "
                              "and context; the segment benchmark keeps the paper's protocol")
    t = time.perf_counter()
    run = evaluate(args.data, method_list(args.methods), args.out, noise=args.noise, split=args.split,
                   limit=args.limit, workers=args.workers, model=args.model, device=args.device,
                   examples=args.examples, noise_seed=args.noise_seed, progress=not args.quiet,
                   scheduler=args.scheduler, allow_unverified=args.allow_unverified, timeout=args.timeout,
                   batch=args.batch, tta=args.tta, retry_failed=args.retry_failed, track=args.track)
    meta, results = load_results(run)
    s = summarize(results)
    for _, r in s.iterrows():
        failed = f", {r['failed']} failed (scored as the farther of coverage 0 and 1)" if r["failed"] else ""
        print(f"noise {r['noise_mm']:g} mm  {r['method']:<14} MAE {r['coverage_mae']:6.2f} points over "
              f"{r['segments'] - r['coverage_undefined']} of {r['segments']} segments{failed}")
    errors = results[results["error"] != ""]
    for name, g in errors.groupby("method"):
        logs = run / "logs" / name
        calls = f"; each program call's standard error and output are in {logs}" if logs.is_dir() else ""
        print(f"colonbench: warning: {name} failed on {len(g)} segment(s); first: "
              f"{with_sample(g['sample_id'].iloc[0], g['error'].iloc[0])} (every one is in "
              f"{run / 'results' / (name + '.csv')}{calls})", file=sys.stderr)
    session = meta["sessions"][-1]
    print(f"wrote {run}/results/: {session['segments']} segment evaluations in {time.perf_counter() - t:.0f} s "
          f"with {session['workers']} worker(s), peak memory {session['peak_process_mib']} MiB per process; "
          f"tables: colonbench leaderboard {run} --out DIR")


def _evaluate_colons(args):
    """colonbench evaluate --task colon: map every whole-colon sample with every method and track."""
    if args.retry_failed:
        raise ColonbenchError("--retry-failed retries segments; a whole-colon map is one unit (a rerun resumes "
                              "maps; to redo failed ones, evaluate into a new run folder)")
    from colonbench.benchmark.colon_evaluate import ALL_METHODS, evaluate_colons, load_colon_results
    from colonbench.reports.colon_leaderboard import colon_table

    t = time.perf_counter()
    methods = list(ALL_METHODS) if args.methods in (None, ["all"]) else method_list(args.methods)
    run = evaluate_colons(args.data, methods, args.out, noise=args.noise, contexts=args.contexts,
                          segment_mm=args.segment_length, split=args.split, limit=args.limit, workers=args.workers,
                          model=args.model, device=args.device, noise_seed=args.noise_seed,
                          progress=not args.quiet, context_model=args.context_model, scheduler=args.scheduler,
                          allow_unverified=args.allow_unverified, timeout=args.timeout, batch=args.batch,
                          tta=args.tta)
    meta, segments, colons = load_colon_results(run)
    tab = colon_table(segments, colons)
    for _, r in tab.iterrows():
        print(f"noise {r['noise_mm']:g} mm  {r['method']:<13} {r['track']:<14} segment MAE {r['segment_mae']:6.2f} "
              f"points over {r['segments']} segments, whole colon |error| {r['whole_mae']:5.2f} points")
    print(f"wrote {run}/results/ in {time.perf_counter() - t:.0f} s; tables: colonbench leaderboard {run} --out DIR")


def cmd_leaderboard(args):
    """Rebuild the leaderboard tables (and figures) from stored runs; with --html, the leaderboard site."""
    from colonbench.reports.leaderboard import write_leaderboard

    if args.html:
        from colonbench.reports.site import write_site

        site = write_site(args.runs, args.out, figures=not args.no_figures, shipped=not args.no_shipped,
                          submitted=not args.no_submitted)
        print(f"wrote the leaderboard site {args.out}: {len(site['pages'])} page(s) ({', '.join(site['pages'])}) "
              f"and {len(site['methods'])} method page(s); open {site['index'].resolve().as_uri()}")
        return
    if args.no_shipped or args.no_submitted:
        raise ColonbenchError("--no-shipped and --no-submitted are for --html (without it the tables hold the runs "
                              "alone unless --shipped or --submitted)")
    extra, notes = _published_for(args.runs, args.shipped, args.submitted) if args.shipped or args.submitted \
        else ([], [])
    result = write_leaderboard(args.runs, args.out, figures=not args.no_figures, extra=extra, notes=notes)
    print(result["markdown"])
    print(f"wrote {', '.join(p.name for p in result['paths'])} to {args.out}")


def _published_for(run_dirs, shipped: bool, submitted: bool) -> tuple[list, list[str]]:
    """The shipped and/or submitted results of the suite and track the runs evaluated, less the methods they hold,
    and the notes on the submitted ones left out (colonbench.benchmark.submitted.leaderboard_items)."""
    from colonbench.benchmark import suites, tracks
    from colonbench.benchmark.runfolder import read_run
    from colonbench.benchmark.submitted import leaderboard_items

    runs = [read_run(r) for r in run_dirs]
    rec = runs[0].get("suite") if runs else None
    if not rec:
        raise ColonbenchError(f"{run_dirs[0]} is not a run of a named suite: there are no shipped or submitted "
                              "results for it")
    if not rec.get("verified"):
        raise ColonbenchError(f"{run_dirs[0]}: its data is not the published {rec['id']} (unverified); the shipped "
                              "and submitted results are not comparable")
    track = tracks.of_run(runs[0])
    try:
        suite = suites.get(rec["id"])
    except InputError:      # a suite built on this machine (colonbench suites build) under another data folder
        raise ColonbenchError(f"{rec['id']}: no shipped results (a suite built on this machine has none)") from None
    items, notes = leaderboard_items(suite, track, mine={m for r in runs for m in r["methods"]}, shipped=shipped,
                                     submitted=submitted)
    if not items and shipped and not submitted:
        raise ColonbenchError(f"no shipped results of {rec['id']} on the {tracks.label(track)} to merge")
    return items, notes


def cmd_methods(args):
    """List the registered methods."""
    from colonbench.benchmark.registry import available

    for name, target in sorted(available().items()):
        print(f"{name:<14} {target}")


def add_parsers(sub) -> None:
    """Add ``evaluate``, ``leaderboard``, ``methods`` to the ``colonbench`` subparsers."""
    p = sub.add_parser("evaluate", help="run methods over a dataset's test shards into a run folder (resumable)")
    p.add_argument("data", help="dataset folder (colonbench generate)")
    p.add_argument("--methods", action="append",
                   help="comma-separated registered names, package.module:Class, predictions:DIR, or one "
                        "'exec:PROGRAM ARGS' per --methods (default all: the paper's method, its baselines and the "
                        "reference rows; see colonbench methods)")
    p.add_argument("--noise", type=floats, default=[0.0, 0.5],
                   help="input noise sigmas, mm, comma-separated (default 0,0.5)")
    p.add_argument("--out", required=True, help="run folder (a rerun finishes it or adds methods)")
    p.add_argument("--split", default="test", help="split to evaluate (default test)")
    p.add_argument("--limit", type=positive(int), help="only this many samples, spread evenly over the split")
    p.add_argument("--workers", type=positive(int), default=1, help="processes (default 1)")
    add_model_args(p, "model .safetensors for the methods built on the network, or a shipped model by name "
                       "(default: small)")
    p.add_argument("--examples", type=int, default=3, help="segments whose meshes are kept for figures (default 3)")
    p.add_argument("--noise-seed", type=int, default=0, help="root seed of the input noise (default 0)")
    add_suite_check_args(p, "the data and run folders")
    benchmark_verbs.add_external_args(p)
    benchmark_verbs.add_track_arg(p, "each segment's length_mm is given to the methods that take it")
    p.add_argument("--task", choices=["segments", "colon"],
                   help="segments (the paper's protocol) or colon (whole-colon maps, docs/mapping.md); "
                        "default: what the dataset was made for")
    p.add_argument("--contexts", type=floats, default=[0.0, CONTEXT_MM],
                   help=f"--task colon: context margins, one track each, mm (0 = segment-only; default 0,"
                        f"{CONTEXT_MM:g})")
    p.add_argument("--segment-length", type=finite, default=SEGMENT_MM,
                   help=f"--task colon: segment arc length of the maps, mm (default {SEGMENT_MM:g})")
    p.add_argument("--context-model", help="--task colon: an in-context model for the tracks with context (the "
                                           "segment-only track keeps --model; docs/mapping.md)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_evaluate)

    p = sub.add_parser("leaderboard", help="tables (md, csv, json) and figures from stored runs on the same data; "
                                           "--html: a static web site of runs on any suites")
    p.add_argument("runs", nargs="+", metavar="RUN", help="run folders (colonbench evaluate, score); with --html also "
                                                          "colonbench benchmark --out folders")
    p.add_argument("--out", required=True, help="folder for leaderboard.md/.csv/.json and the figures; with --html "
                                                "the site (OUT/index.html; a site made before is replaced)")
    p.add_argument("--html", action="store_true", help="write a static site: one page per suite and track, one per "
                                                       "method, sortable tables, the shipped results merged "
                                                       "(docs/benchmark.md, The leaderboard page)")
    p.add_argument("--no-figures", action="store_true", help="tables only")
    shipped = p.add_mutually_exclusive_group()
    shipped.add_argument("--shipped", action="store_true", help="merge the shipped reference results of the runs' "
                                                                "suite (methods the runs hold are left out of them; "
                                                                "--html does by default)")
    shipped.add_argument("--no-shipped", action="store_true", help="--html: leave the shipped results out")
    submitted = p.add_mutually_exclusive_group()
    submitted.add_argument("--submitted", action="store_true", help="merge the submitted results of the runs' suite "
                                                                    "and track (the repository's results/; those "
                                                                    "named as a method of the runs are left out, and "
                                                                    "the tables say so; --html does by default)")
    submitted.add_argument("--no-submitted", action="store_true", help="--html: leave the submitted results out")
    p.set_defaults(func=cmd_leaderboard)

    p = sub.add_parser("methods", help="list the registered coverage-estimation methods")
    p.set_defaults(func=cmd_methods)
