"""``colonbench benchmark``, ``export`` and ``score``: the benchmark release's verbs (``suites``: :mod:`.suites`)."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from colonbench.commands.common import add_suite_check_args


def parse_methods(values) -> list[str]:
    """Method specs from ``--methods`` values: comma-separated names, except that a value holding ``exec:`` is one
    program's command line (commas and all); ``all`` is every built-in method."""
    from colonbench.benchmark.registry import DEFAULT_METHODS

    specs = []
    for value in values or ():
        if "exec:" in value:
            specs.append(value.strip())
        else:
            specs += [m.strip() for m in value.split(",") if m.strip()]
    return list(DEFAULT_METHODS) if specs == ["all"] else specs


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text}")
    return value


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be 1 or more, got {text}")
    return value


def add_external_args(p) -> None:
    """``--timeout`` and ``--batch`` of ``exec:`` methods."""
    p.add_argument("--timeout", type=_positive_float, help="exec: methods: seconds allowed per input file (a call "
                   "gets that times its files; default 300)")
    p.add_argument("--batch", type=_positive_int, help="exec: methods: input files per program call (default 64)")
    p.add_argument("--retry-failed", action="store_true",
                   help="evaluate again the segments a method failed on in this --out (an exec: program runs on "
                        "them again); the other rows are kept")


def add_track_arg(p, what: str) -> None:
    """``--track points|length``: what the methods are given besides the points (colonbench.benchmark.tracks)."""
    from colonbench.benchmark.tracks import DEFAULT, TRACKS

    p.add_argument("--track", choices=TRACKS, default=DEFAULT,
                   help=f"points (the default: the cloud only) or length, the known-length track: {what} "
                        "(docs/benchmark.md, Tracks)")


def _add_data_args(p) -> None:
    p.add_argument("--data", help="where suite data is cached (default $COLONBENCH_DATA, else "
                   "$XDG_CACHE_HOME/colonbench/suites, else ~/.cache/colonbench/suites): one folder per suite, "
                   "made where missing")
    p.add_argument("--workers", type=_positive_int, default=1, help="local processes (default 1)")
    add_suite_check_args(p)
    p.add_argument("--quiet", action="store_true", help="no progress bars")


def cmd_benchmark(args):
    """Evaluate methods on named suites (data made where missing) and write the cross-suite leaderboard."""
    from colonbench.pipeline import RunFailed, run_benchmark

    t = time.perf_counter()
    methods = parse_methods(args.methods)
    try:
        result = run_benchmark(methods, args.suites, args.out, data=args.data, workers=args.workers,
                               scheduler=args.scheduler, model=args.model, device=args.device,
                               allow_unverified=args.allow_unverified, shipped=not args.no_shipped,
                               submitted=not args.no_submitted,
                               timeout=args.timeout, batch=args.batch, figures=not args.no_figures,
                               progress=not args.quiet, retry_failed=args.retry_failed, track=args.track)
    except RunFailed as exc:  # no tables: the warnings say what failed, then the error
        warn_failures(exc.failures, lambda suite: Path(args.out) / "runs" / suite / "results")
        raise
    print(result["markdown"])
    for suite, sec in result["seconds"].items():
        print(f"{suite}: data {sec['data_seconds']:.0f} s, evaluation {sec['evaluate_seconds']:.0f} s")
    warn_failures(result["failures"], lambda suite: Path(args.out) / "runs" / suite / "results")
    print(f"wrote {args.out}/leaderboard.md (.csv, .json) and suites/<suite>/ in {time.perf_counter() - t:.0f} s")


def warn_failures(failures, where) -> None:
    """One warning on stderr per suite, method and noise level with failed samples, naming the first failure and
    its sample.

    Parameters
    ----------
    failures : DataFrame
        :func:`colonbench.pipeline.failures` rows.
    where : callable
        The results folder of a suite id, for the message.
    """
    from colonbench.pipeline import with_sample

    for _, r in failures[failures["failed"] > 0].iterrows():
        logs = Path(where(r["suite"])).parent / "logs" / r["method"]
        calls = f"; each program call's standard error and output are in {logs}" if logs.is_dir() else ""
        print(f"colonbench: warning: {r['method']} failed on {r['failed']} of {r['samples']} samples of "
              f"{r['suite']} at noise {r['noise_mm']:g} mm, scored as the farther of coverage 0 and 1; first: "
              f"{with_sample(r['first_sample'], r['first_error'])} (every one is in {where(r['suite'])}{calls})",
              file=sys.stderr)


def cmd_export(args):
    """Write a suite's inputs (one PLY per cloud, noise added, and index.csv; no truth) for offline methods."""
    from colonbench.pipeline import export_suite

    info = export_suite(args.suite, args.out, data=args.data, workers=args.workers, scheduler=args.scheduler,
                        allow_unverified=args.allow_unverified, progress=not args.quiet, track=args.track)
    rec = info["suite"]
    track = "" if args.track == "points" else f" --track {args.track}"
    print(f"wrote {info['inputs']} inputs of {rec['id']} ({rec['signature']}, {rec['check']}){track} to {args.out}; "
          f"predict PRED_DIR/<sample_id>.json for each, then colonbench score {rec['id']} PRED_DIR --out "
          f"RUN{track}{_data_flag(args)}")


def cmd_score(args):
    """Score a folder of predictions (<sample_id>.json) on a suite into a run folder."""
    import pandas as pd

    from colonbench.benchmark import suites
    from colonbench.benchmark.evaluate import load_results
    from colonbench.pipeline import FAILURE_COLUMNS, failures, score_suite
    from colonbench.benchmark.summary import summarize

    run = score_suite(args.suite, args.predictions, args.out, name=args.name, data=args.data, workers=args.workers,
                      scheduler=args.scheduler, allow_unverified=args.allow_unverified, progress=not args.quiet,
                      track=args.track)
    from colonbench.benchmark.colon_evaluate import is_colon_run

    if not is_colon_run(run):
        _, results = load_results(run)
        for _, r in summarize(results).iterrows():
            failed = (f", {r['failed']} without a valid prediction (scored as the farther of coverage 0 and 1)"
                      if r["failed"] else "")
            print(f"noise {r['noise_mm']:g} mm  {r['method']}: MAE {r['coverage_mae']:.2f} points over "
                  f"{r['segments'] - r['coverage_undefined']} of {r['segments']} segments{failed}")
    warn_failures(pd.DataFrame(failures(suites.get(args.suite, args.data), run), columns=FAILURE_COLUMNS),
                  lambda suite: run / "results")
    print(f"wrote {run}; the leaderboard with the shipped results: colonbench leaderboard {run} --out DIR "
          f"--shipped, or colonbench benchmark --suites {args.suite} --methods predictions:{args.predictions} "
          f"--out DIR{_data_flag(args)}" + (f" --track {args.track}" if getattr(args, "track", "points") != "points"
                                            else ""))


def _data_flag(args) -> str:
    """`` --data DIR`` when the command was given one (for the next command it suggests)."""
    return f" --data {args.data}" if args.data else ""


def add_parsers(sub) -> None:
    """Add ``benchmark``, ``export`` and ``score`` to the ``colonbench`` subparsers."""
    p = sub.add_parser("benchmark", help="evaluate methods on named suites and write one cross-suite leaderboard",
                       description="Evaluate methods on named suites and write one cross-suite leaderboard, the "
                                   "built-in methods' shipped results merged in. Suite data is generated where "
                                   "missing (cached, resumable) and checked against its published hash.")
    p.add_argument("--methods", action="append", metavar="M1,M2",
                   help="methods: registered names (colonbench methods), package.module:Class, "
                        "'exec:PROGRAM ARGS' (called as PROGRAM ARGS FILE... --out-dir DIR, writing "
                        "DIR/<name>.json as colonbench estimate does) or predictions:DIR; NAME=... names the row. "
                        "Repeat --methods for several exec: programs. None: the shipped results only")
    p.add_argument("--suites", default="demo-v1", help="comma-separated suite ids, or all (default demo-v1, the "
                                                      "smoke test; colonbench suites lists them)")
    p.add_argument("--out", required=True, help="benchmark folder: leaderboard.md/.csv/.json, suites/<suite>/, "
                                                "runs/<suite>/ (a rerun finishes or extends it)")
    _add_data_args(p)
    p.add_argument("--model", help="model for the built-in methods on the network (default: the shipped one)")
    p.add_argument("--device", default="cpu", help="cpu, cuda, auto (default cpu)")
    add_external_args(p)
    p.add_argument("--no-shipped", action="store_true", help="leave the shipped reference results out")
    p.add_argument("--no-submitted", action="store_true", help="leave the submitted results (the repository's "
                                                               "results/) out")
    p.add_argument("--no-figures", action="store_true", help="tables only")
    add_track_arg(p, "each segment's nominal arc length is given to the methods that take it (exec: programs get "
                     "--length-mm L); --suites all leaves out colon-v1, which has no such track")
    p.set_defaults(func=cmd_benchmark)

    p = sub.add_parser("export", help="write a suite's inputs (one PLY per cloud, an index; no truth) for "
                                      "methods run elsewhere",
                       description="Write a suite's inputs only, for a method run outside colonbench: one PLY per "
                                   "evaluated cloud (noise added), named by its sample id, index.csv and suite.json; "
                                   "no truth. Score the predictions with colonbench score.")
    p.add_argument("suite", help="suite id or name (colonbench suites)")
    p.add_argument("--out", required=True, help="folder for the PLY files, index.csv and suite.json")
    _add_data_args(p)
    add_track_arg(p, "index.csv adds each input's length_mm")
    p.set_defaults(func=cmd_export)

    p = sub.add_parser("score", help="score a folder of predictions (<sample_id>.json) on a suite into a run folder",
                       description="Score a folder of predictions, PRED_DIR/<sample_id>.json in the JSON of "
                                   "colonbench estimate, on a suite into a run folder (docs/formats.md).")
    p.add_argument("suite", help="suite id or name (colonbench suites)")
    p.add_argument("predictions", help="folder of <sample_id>.json predictions")
    p.add_argument("--out", required=True, help="run folder to write")
    p.add_argument("--name", help="the method's row name (default: the predictions folder's name)")
    _add_data_args(p)
    add_track_arg(p, "the predictions were made with each input's length (export --track length)")
    p.set_defaults(func=cmd_score)

