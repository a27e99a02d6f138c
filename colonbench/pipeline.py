"""The benchmark's pipelines, across the layers: one command from suite data to leaderboards, export and score.

This module sits above the data-flow packages (as the command line does) because a benchmark run generates
data (``shards``), evaluates (``benchmark``) and writes reports (``reports``).

:func:`run_benchmark` is ``colonbench benchmark`` (and ``colonbench.benchmark(...)`` from Python):

1. each suite's data is generated where it is missing into the data folder
   (``root/<suite id>``, cached and resumable) and checked against its
   published content hash;
2. the methods are evaluated on it into ``RUN/runs/<suite id>/`` (a run
   folder of ``colonbench evaluate``: resumable, in parallel or on Dask);
3. the shipped reference results of the built-in methods
   (:mod:`colonbench.benchmark.shipped`) and the submitted results of the
   repository's ``results/`` (:mod:`colonbench.benchmark.submitted`) join
   them, except for methods the user evaluated themselves;
4. per suite ``RUN/suites/<suite id>/leaderboard.md`` (and ``.csv``, ``.json``,
   breakdowns, figures), and across suites ``RUN/leaderboard.md``, ``.csv``
   and ``.json`` (:mod:`colonbench.reports.benchmark_report`); unless a
   method it evaluated gave no estimate on any sample: then it writes no
   tables (:class:`RunFailed`).

:func:`export_suite` and :func:`score_suite` are the offline route: inputs
written as files, predictions made anywhere, then scored into a run folder
that ``colonbench leaderboard`` (or :func:`write_report`) merges with the
shipped results.
"""

from __future__ import annotations

import time
from pathlib import Path

from colonbench.benchmark import suites, tracks
from colonbench.errors import ColonbenchError, InputError
from colonbench.progress import bar as progress_bar

#: Columns of :func:`failures`.
FAILURE_COLUMNS = ["suite", "method", "noise_mm", "samples", "failed", "first_error", "first_sample"]


class RunFailed(ColonbenchError):
    """A method that :func:`run_benchmark` evaluated gave no estimate on any sample: it wrote no tables.

    Attributes
    ----------
    failures : DataFrame
        :func:`failures` of every suite evaluated.
    """

    def __init__(self, message: str, failures):
        super().__init__(message)
        self.failures = failures


def _evaluate(suite, data, methods, run_dir, retry_failed: bool = False, track: str = tracks.DEFAULT, **kw) -> Path:
    from colonbench.benchmark.colon_evaluate import evaluate_colons
    from colonbench.benchmark.evaluate import evaluate

    if suite.task == "colon":   # a map is one unit: it is resumed, not retried
        return evaluate_colons(data, methods, run_dir, noise=suite.noise_mm, contexts=suite.contexts_mm,
                               segment_mm=suite.segment_mm, split=suite.split, limit=suite.limit,
                               noise_seed=suite.noise_seed, **kw)
    return evaluate(data, methods, run_dir, noise=suite.noise_mm, split=suite.split, limit=suite.limit,
                    noise_seed=suite.noise_seed, retry_failed=retry_failed, track=track, **kw)


def _check_suite_run(run_dir: Path, suite) -> None:
    from colonbench.benchmark.runfolder import read_run

    rec = read_run(run_dir).get("suite") or {}
    if rec.get("id") != suite.id:
        raise InputError(f"{run_dir}: the data evaluated is not suite {suite.id} (it was made from another manifest "
                         "or selection); use a new data folder")


def run_benchmark(methods=(), suites_=("demo-v1",), out="runs/benchmark", data=None, workers: int = 1,
                  scheduler=None, model=None, device: str = "cpu", allow_unverified: bool = False,
                  shipped: bool = True, timeout: float | None = None, batch: int | None = None,
                  figures: bool = True, progress: bool = True, retry_failed: bool = False,
                  track: str = tracks.DEFAULT, submitted: bool = True) -> dict:
    """Evaluate methods on named suites and write the cross-suite leaderboard, of one track.

    Parameters
    ----------
    methods : list of str or method objects
        Registered names, ``module:Class``, ``exec:PROGRAM ARGS``, ``predictions:DIR`` (``NAME=`` before any
        of them names its row), or objects with ``name`` and ``estimate(points)``. May be empty: the
        shipped results alone.
    suites_ : str or list of str or Suite
        Suite ids or names, or ``"all"``.
    out : path
        The benchmark run folder.
    data : path, optional
        Where suite data is cached (default :func:`colonbench.benchmark.suites.default_data_root`).
    workers, scheduler
        Local processes, or a Dask scheduler address, for generating and evaluating.
    model, device
        For the built-in methods built on the network.
    allow_unverified : bool
        Evaluate suite data whose content hash is not the published one (results say ``unverified``; the
        shipped results then stay out).
    shipped : bool
        Merge the shipped reference results.
    submitted : bool
        Merge the submitted results of the same suites and track (the repository's ``results/``; none for an
        installed colonbench), less those named as a method evaluated here.
    timeout, batch
        ``exec:`` methods: seconds per input, inputs per call.
    figures, progress : bool
    retry_failed : bool
        Evaluate again the segments a method failed on in ``out``'s runs (segment suites; the other rows are
        kept), then rebuild the tables.
    track : str
        ``points`` (the cloud only) or ``length``: each segment's nominal arc length is given to the methods that
        take it (:mod:`colonbench.benchmark.tracks`), and that track's shipped results are merged. ``suites_="all"``
        then leaves out the whole-colon suite, which has no such track; named, it is refused.

    Returns
    -------
    dict
        ``summary`` (the cross-suite table), ``markdown``, ``paths`` (written files), ``runs`` (per suite id),
        ``seconds`` (per suite id), ``failures`` (:func:`failures` of every suite evaluated).

    Raises
    ------
    RunFailed
        A method evaluated here gave no estimate on any sample of any suite. No tables are written, and those an
        earlier run left in ``out`` (``leaderboard.*``, ``suites/<suite id>/`` of these suites) are removed, since
        they no longer describe its runs; ``out/runs/<suite id>/`` keeps every sample's row with its error.
    """
    from colonbench.reports.benchmark_report import write_report

    from colonbench.benchmark.evaluate import method_list

    from colonbench.benchmark.registry import check_spec

    track = tracks.check(track)
    chosen = suites.parse(suites_, data)
    if track != tracks.DEFAULT:
        if suites_ == "all" or isinstance(suites_, (list, tuple)) and list(suites_) == ["all"]:  # those with it
            chosen = [s for s in chosen if s.task != "colon"]
        for s in chosen:
            tracks.check(track, s)
    methods = method_list(methods)
    if not methods and not shipped and not submitted:
        raise InputError("no methods to evaluate, --no-shipped and --no-submitted: nothing to show")
    for spec in methods:  # a program or script that is not there: refused before any data is made or written
        if isinstance(spec, str):
            check_spec(spec)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    runs, timing = {}, {}
    for suite in chosen:
        if not methods:
            continue
        t0 = time.perf_counter()
        data_dir = suites.ensure_data(suite, data, workers=workers, scheduler=scheduler, progress=progress)
        t1 = time.perf_counter()
        run_dir = out / "runs" / suite.id
        _evaluate(suite, data_dir, methods, run_dir, workers=workers, scheduler=scheduler, model=model,
                  device=device, progress=progress, allow_unverified=allow_unverified, timeout=timeout, batch=batch,
                  retry_failed=retry_failed, track=track)
        _check_suite_run(run_dir, suite)
        runs[suite.id] = run_dir
        timing[suite.id] = {"data_seconds": round(t1 - t0, 1), "evaluate_seconds": round(time.perf_counter() - t1, 1)}
    import pandas as pd

    by_id = {s.id: s for s in chosen}
    failed = pd.DataFrame([row for sid, run_dir in runs.items() for row in failures(by_id[sid], run_dir)],
                          columns=FAILURE_COLUMNS)
    dead = _dead(failed, methods, runs)
    if dead:
        _remove_tables(out, chosen)
        first = failed[failed["method"] == dead[0]].iloc[0]
        raise RunFailed(f"{', '.join(dead)} failed on every sample (first, {first['suite']} at noise "
                        f"{first['noise_mm']:g} mm: {with_sample(first['first_sample'], first['first_error'])}); no "
                        "leaderboard was written: every "
                        f"sample's row and its error are in {out / 'runs'}/<suite>/results", failed)
    result = write_report(out, chosen, runs, shipped=shipped, figures=figures, track=track, submitted=submitted)
    result["runs"], result["seconds"], result["failures"] = runs, timing, failed
    return result


def with_sample(sample: str, error: str) -> str:
    """A failure's error, after its sample id where the error does not name it already."""
    return error if not sample or sample in error else f"{sample}: {error}"


def failures(suite, run_dir) -> list[dict]:
    """What failed in a suite's finished run folder, per method and noise level.

    A segment suite's samples are its segments; a whole-colon suite's are the segments of its headline track's
    maps that the map gave the method (:func:`~colonbench.benchmark.colon_evaluate.skipped_rows`), and each map
    that failed as a whole.

    Returns
    -------
    list of dict
        :data:`FAILURE_COLUMNS`: ``samples``, ``failed`` (rows with an error), ``first_error`` (the first of
        them at that noise level, "" for none) and ``first_sample``, its sample id (a whole-colon map's segment:
        ``<sample id>_seg<k>``).
    """
    import pandas as pd

    from colonbench.benchmark.exchange import sample_id, segment_id

    if suite.task == "colon":
        from colonbench.benchmark.colon_evaluate import load_colon_results, skipped_rows

        _, segs, colons = load_colon_results(run_dir)
        maps = colons[(colons["track"] == suite.headline_track) & (colons["error"] != "")]
        segs = segs[segs["track"] == suite.headline_track]
        segs = segs[~skipped_rows(segs)]          # given to no method: neither a sample nor a failure of one
        rows = pd.concat([maps, segs], ignore_index=True)
        rows["sample_id"] = [sample_id(*key) if seg != seg else segment_id(sample_id(*key), seg)   # NaN: a map
                             for *key, seg in zip(rows["shard"], rows["index"], rows["noise_mm"], rows["segment"])]
    else:
        from colonbench.benchmark.evaluate import load_results

        _, rows = load_results(run_dir)
    out = []
    for (method, noise), g in rows.groupby(["method", "noise_mm"], sort=True):
        errors = g["error"].fillna("").astype(str)
        errors = errors[errors != ""]
        out.append({"suite": suite.id, "method": method, "noise_mm": float(noise), "samples": len(g),
                    "failed": len(errors), "first_error": errors.iloc[0] if len(errors) else "",
                    "first_sample": str(g.loc[errors.index[0], "sample_id"]) if len(errors) else ""})
    return out


def _dead(failed, methods, runs: dict) -> list[str]:
    """The methods of this call (by spec or object) that failed on every sample of every suite."""
    from colonbench.benchmark.runfolder import read_run

    specs = {m for m in methods if isinstance(m, str)}
    objects = {getattr(m, "name", None) for m in methods if not isinstance(m, str)}
    mine = {name for run_dir in runs.values() for name, rec in read_run(run_dir)["methods"].items()
            if rec.get("spec") in specs or (rec.get("spec") is None and name in objects)}
    from colonbench.benchmark.summary import failed_every

    return sorted(m for m, g in failed.groupby("method") if m in mine and failed_every(g["samples"], g["failed"]))


def _remove_tables(out: Path, chosen) -> None:
    """Remove the tables an earlier run wrote in a benchmark folder (its runs are left)."""
    import shutil

    for name in ("leaderboard.md", "leaderboard.csv", "leaderboard.json"):
        (out / name).unlink(missing_ok=True)
    for suite in chosen:
        shutil.rmtree(out / "suites" / suite.id, ignore_errors=True)


def export_suite(suite, out, data=None, workers: int = 1, scheduler=None, allow_unverified: bool = False,
                 progress: bool = True, track: str = tracks.DEFAULT) -> dict:
    """Write a suite's inputs only: one PLY per evaluated cloud (noise added), ``index.csv``, ``suite.json``.

    A whole-colon suite's inputs are the clouds of the segments its maps estimate, cut by colonbench's own
    map of each noisy reconstruction (what a segment method is given in its tracks). On the known-length track
    (``track="length"``, segment suites) ``index.csv`` adds each input's ``length_mm``, the segment's nominal
    arc length, which the points track withholds.

    Returns
    -------
    dict
        ``suite.json``'s content: ``suite``, ``track``, ``inputs``, ``contract``.
    """
    from colonbench.benchmark import exchange
    from colonbench.benchmark.evaluate import select
    from colonbench.benchmark.runfolder import write_json

    suite = suites.get(suite, data)
    track = tracks.check(track, suite)
    out = Path(out)
    if out.exists() and any(p for p in out.iterdir() if p.name != exchange.EXPORT_NAME and p.suffix != ".ply"
                            and p.name != exchange.INDEX_NAME):
        raise InputError(f"{out} holds other files; export into a new or empty folder")
    data_dir = suites.ensure_data(suite, data, workers=workers, scheduler=scheduler, progress=progress)
    record = suites.verify(suite, data_dir, allow_unverified)
    out.mkdir(parents=True, exist_ok=True)
    _, picks = select(data_dir, suite.split, suite.limit)
    rows = []
    bar = progress_bar(total=sum(len(i) for _, i in picks) * len(suite.noise_mm), unit="sample", desc="export",
                       enabled=progress)
    for shard_name, indices in picks:
        for i in indices:
            for sigma in suite.noise_mm:
                sid = exchange.sample_id(shard_name, i, sigma)
                for name, pts, length in _inputs(suite, data_dir, shard_name, i, sigma, sid):
                    exchange.write_input(out / f"{name}.ply", pts)
                    rows.append({"sample_id": name, "file": f"{name}.ply", "noise_mm": sigma, "points": len(pts),
                                 **({"length_mm": length} if track == "length" else {})})
                bar.update(1)
    bar.close()
    exchange.write_index(out, rows, track)
    info = {"suite": record, "track": track, "inputs": len(rows), "contract": "docs/formats.md: colonbench score "
            f"SUITE PRED_DIR{'' if track == tracks.DEFAULT else ' --track ' + track} reads PRED_DIR/<sample_id>.json "
            "with coverage, holes, centerline (mm, the input's frame)"}
    write_json(out / exchange.EXPORT_NAME, info)
    return info


def _inputs(suite, data_dir, shard_name, i, sigma, sid):
    from colonbench.benchmark.evaluate import noisy

    if suite.task == "colon":
        from colonbench.benchmark.colon_evaluate import segment_inputs
        from colonbench.errors import ColonbenchError
        from colonbench.mapping.reconstruction_centerline import colon_centerline
        from colonbench.shards.colonshard import ColonShard

        sample = ColonShard(Path(data_dir) / shard_name).sample(i)
        points = noisy(sample["points"], sigma, suite.noise_seed, shard_name, i)
        try:
            pieces = colon_centerline(points, positions=sample["positions"])
        except ColonbenchError:
            pieces = None
        return [(*x, None) for x in segment_inputs(points, sample["positions"], pieces, suite.segment_mm, sid)]
    from colonbench.shards.reader import Shard

    with Shard(Path(data_dir) / shard_name) as shard:
        geo = shard.geometry(i)
        return [(sid, noisy(geo["partial_points"], sigma, suite.noise_seed, shard_name, i), float(geo["length_mm"]))]


def score_suite(suite, predictions, out, name: str | None = None, data=None, workers: int = 1, scheduler=None,
                allow_unverified: bool = False, progress: bool = True, track: str = tracks.DEFAULT) -> Path:
    """Score a folder of predictions (``<sample_id>.json``) on a suite into a run folder of ``track`` (the track
    the predictions were made on: ``length`` for those of an export with ``--track length``).

    Returns
    -------
    Path
        The run folder (``colonbench leaderboard RUN`` merges it with the shipped results' run folders, or
        ``colonbench benchmark --methods predictions:DIR`` does all at once).
    """
    suite = suites.get(suite, data)
    track = tracks.check(track, suite)
    folder = Path(predictions)
    if not folder.is_dir():
        raise InputError(f"{folder}: no such folder of predictions")
    if not any(folder.glob("*.json")):
        raise InputError(f"{folder}: no <sample_id>.json predictions in it (docs/formats.md)")
    data_dir = suites.ensure_data(suite, data, workers=workers, scheduler=scheduler, progress=progress)
    check_prediction_names(suite, data_dir, folder)
    spec = f"{name or folder.resolve().name}=predictions:{folder}"
    _evaluate(suite, data_dir, [spec], Path(out), workers=workers, scheduler=scheduler, progress=progress,
              allow_unverified=allow_unverified, track=track)
    _check_suite_run(Path(out), suite)
    return Path(out)


def check_prediction_names(suite, data_dir, folder: Path) -> tuple[int, int]:
    """How many of a folder's ``.json`` files are named by a sample id of ``suite``, and how many are not.

    Raises
    ------
    InputError
        None is: the files are named otherwise than ``colonbench export`` names the inputs.
    """
    from colonbench.benchmark.evaluate import select
    from colonbench.benchmark.exchange import sample_id

    _, picks = select(data_dir, suite.split, suite.limit)
    ids = {sample_id(n, i, s) for n, idx in picks for i in idx for s in suite.noise_mm}
    stems = [p.stem for p in Path(folder).glob("*.json")]
    if suite.task == "colon":   # a map's segments: <sample id>_seg<k>
        ok = [x for x in stems if x.rpartition("_seg")[0] in ids]
    else:
        ok = [x for x in stems if x in ids]
    if not ok:
        example = sorted(ids)[0] + ("_seg000" if suite.task == "colon" else "")
        raise InputError(f"{folder}: none of its {len(stems)} .json files is named by a sample id of {suite.id} "
                         f"(such as {example}.json): name each prediction as colonbench export names its input")
    return len(ok), len(stems) - len(ok)

