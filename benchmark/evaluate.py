"""The benchmark harness: methods over the test shards of a dataset, per segment, resumable, in parallel.

A run folder holds::

    run.json                    what was evaluated: data identity, track, noise levels and seed,
                                metric settings, methods with versions, package versions
    parts/<method>/<unit>.csv   per-segment rows of one shard at one noise level (resume points)
    results/<method>.csv        every per-segment row of a method, once all its parts exist
    results/<method>.json       its summary (colonbench.benchmark.summary) with the run's settings
    examples/<method>/*.npz     a few segments' completed meshes, for the Fig. 5 triplets
    predictions/<method>/       an exec: program's answers; logs/<method>/ its calls' output

One unit of work is one shard at one noise level. Each worker process loads
the methods once; for every segment of a unit the noise is drawn once
(stream ``("eval-noise", sigma in um, shard, index)`` under ``noise_seed``, so
every method and every rerun sees the same noisy cloud), and methods built on
the network share its prediction (:func:`colonbench.completion.method.shared_predictor`).
A method that raises on a segment gets a row with the error and NaN metrics;
the leaderboard counts these rows and scores them as failures
(:func:`colonbench.benchmark.summary.scored_errors`), it never drops them.

A rerun with the same data, noise and methods finishes what is missing (a
warning counts the failures it keeps); with ``retry_failed`` it also
evaluates again the segments whose rows hold an error. A rerun with more methods adds them to the run; a method whose version
changed is refused (start a new run folder).
"""

from __future__ import annotations

import hashlib
import json
import logging
import resource
import time
from pathlib import Path

import numpy as np
import pandas as pd

from colonbench import seeding
from colonbench.benchmark.exchange import sample_id, with_sample_ids
from colonbench.benchmark.metrics import COUNT_COLUMNS, THRESHOLDS_MM, point_counts, segment_metrics
from colonbench.benchmark import tracks
from colonbench.benchmark.parallel import run_units
from colonbench.benchmark.registry import load_method
from colonbench.estimate import as_estimate
from colonbench.benchmark.runfolder import (RUN_FILE, RunMismatch, begin_run, check_run_folder, read_rows, read_run,
                                            save_example, write_csv, write_json)
from colonbench.benchmark.summary import metric_columns, summarize
from colonbench.completion.symmetry import check_tta
from colonbench.errors import ColonbenchError, InputError
from colonbench.folderlock import folder_lock

__all__ = ["RUN_FILE", "RunMismatch", "evaluate", "load_results", "noisy", "read_rows", "result_columns", "select"]

#: Per-segment columns, in order (then the metric columns, ``seconds`` and ``error``).
ID_COLUMNS = ["method", "shard", "index", "colon_id", "length_mm", "hole_model", "noise_mm", "true_coverage",
              "coverage", "coverage_error", "interval_low", "interval_high", "review"]


def result_columns() -> list[str]:
    """Columns of a per-segment results CSV (the point counts after the metrics: rows made before version 1.1
    have none; ``sample_id`` last, the id of the input, filled in on reading rows made before it was kept)."""
    return ID_COLUMNS + metric_columns() + list(COUNT_COLUMNS) + ["seconds", "error", "sample_id"]


# ---------------------------------------------------------------------------------------------- the data


def read_lock(data: Path) -> dict:
    """A dataset folder's lock (:mod:`colonbench.shards.dataset`), or a clear error."""
    from colonbench.shards.dataset import LOCK_NAME

    path = data / LOCK_NAME
    if not path.is_file():
        raise InputError(f"{data}: no {LOCK_NAME}; generate the dataset first (colonbench generate)")
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise InputError(f"{path}: unreadable ({exc}); run colonbench verify") from None


def select(data, split: str = "test", limit: int | None = None) -> tuple[dict, list[tuple[str, list[int]]]]:
    """The samples a run evaluates.

    Returns
    -------
    identity : dict
        ``manifest_name``, ``manifest_sha256``, ``config_sha256``, ``split``,
        ``samples`` and ``samples_sha256`` (of the shards' sha256 and the
        chosen indices): runs with equal identities evaluated the same data.
    picks : list of (shard name, [index, ...])
        In the lock's order.
    """
    data = Path(data)
    lock = read_lock(data)
    shards = {n: e for n, e in lock.get("shards", {}).items() if e.get("split") == split}
    missing = [n for n in lock.get("missing", []) if n.startswith(f"{split}/")]
    if missing:
        raise InputError(f"{data}: split {split!r} is incomplete ({len(missing)} shard(s) missing, e.g. "
                         f"{missing[0]}); finish it with colonbench generate --splits {split}")
    if not shards:
        raise InputError(f"{data}: no shards of split {split!r}")
    for name, e in shards.items():
        path = data / name
        if not path.is_file() or path.stat().st_size != e["bytes"]:
            raise InputError(f"{path}: missing or not the size its lock records; run colonbench verify {data}")
    kept = lock.get("kept_samples", {})   # a suite archive's subset shards hold only these rows
    flat = [(n, i) for n, e in shards.items() for i in (kept[n] if n in kept else range(int(e["samples"])))]
    if limit is not None:
        if limit < 1:
            raise InputError(f"--limit must be >= 1, got {limit}")
        keep = np.unique(np.linspace(0, len(flat) - 1, min(limit, len(flat))).astype(int))
        flat = [flat[k] for k in keep]
    h = hashlib.sha256()
    picks: dict[str, list[int]] = {}
    for n, i in flat:
        h.update(f"{shards[n]['sha256']} {i}\n".encode())
        picks.setdefault(n, []).append(i)
    identity = {"manifest_name": lock.get("manifest_name"), "manifest_sha256": lock.get("manifest_sha256"),
                "config_sha256": lock.get("config_sha256"), "split": split, "samples": len(flat),
                "samples_sha256": h.hexdigest()}
    return identity, list(picks.items())


def noisy(points: np.ndarray, sigma: float, seed: int, shard: str, index: int) -> np.ndarray:
    """The partial cloud with Gaussian noise of ``sigma`` mm, the same draw for every method and rerun."""
    points = np.asarray(points, dtype=float)
    if sigma <= 0:
        return points
    rng = seeding.rng(seed, "eval-noise", int(round(sigma * 1000)), shard, int(index))
    return points + rng.normal(0.0, sigma, points.shape)


# ---------------------------------------------------------------------------------------------- one unit

def _truth(shard, i: int, geo: dict, needs_heatmap: bool) -> dict:
    truth = {"coverage": geo["coverage"], "hole_points": geo["hole_points"].astype(float),
             "centerline": geo["centerline"].astype(float), "vertices": geo["vertices"].astype(float),
             "faces": geo["faces"]}
    if needs_heatmap:
        truth["target"] = shard.heatmaps(i)[1]
        truth["grid"] = shard.grid(i)
    return truth


def _one(method, pts: np.ndarray, truth: dict, sid: str, length: float | None = None):
    t = time.perf_counter()
    known = {} if length is None else {"length_mm": length}
    if getattr(method, "by_sample", False):  # predictions made outside (colonbench.benchmark.external)
        result = method.predicted(sid)
    elif getattr(method, "uses_truth", False):
        result = method.estimate(pts, truth=truth, **known)
    else:
        result = method.estimate(pts, **known)
    wall = time.perf_counter() - t
    est = as_estimate(result, method.name)
    stages = getattr(est, "seconds", None) or {}
    # shared steps (the network) are counted in full for every method that uses them
    return est, (float(sum(stages.values())) if stages else wall)


def run_unit(data: str, shard_name: str, indices: list[int], sigma: float, noise_seed: int, names: list[str],
             examples: list[int], run_dir: str, track: str = tracks.DEFAULT, *,
             methods: dict) -> dict[str, list[dict]]:
    """Every method in ``names`` on the chosen samples of one shard at one noise level; on the known-length track
    (``track="length"``) the methods that take it are given each sample's ``length_mm``.

    Returns
    -------
    dict
        ``{method name: [per-segment row, ...]}`` (columns: :func:`result_columns`).
    """
    from colonbench.shards.reader import Shard

    chosen = [methods[n] for n in names]
    given = {m.name: track == "length" and tracks.takes_length(m) for m in chosen}
    needs_heatmap = any(getattr(m, "uses_truth", False) for m in chosen)
    out = {n: [] for n in names}
    with Shard(Path(data) / shard_name) as shard:
        for i in indices:
            geo = shard.geometry(i)
            truth = _truth(shard, i, geo, needs_heatmap)
            pts = noisy(geo["partial_points"], sigma, noise_seed, shard_name, i)
            sid = sample_id(shard_name, i, sigma)
            base = {"shard": shard_name, "index": int(i), "colon_id": geo["colon_id"],
                    "length_mm": geo["length_mm"], "hole_model": geo["hole_model"], "noise_mm": float(sigma),
                    "true_coverage": geo["coverage"], "sample_id": sid}
            for m in chosen:
                row = {"method": m.name, **base}
                try:
                    est, seconds = _one(m, pts, truth, sid, float(geo["length_mm"]) if given[m.name] else None)
                    if not np.isfinite(est.coverage):     # no answer: a failure, scored as one (never left out)
                        raise InputError(f"{m.name} gave no coverage (NaN)")
                except Exception as exc:  # noqa: BLE001 - recorded in the row and counted in the tables
                    msg = str(exc) if isinstance(exc, ColonbenchError) else f"{type(exc).__name__}: {exc}"
                    row.update({"coverage": np.nan, "coverage_error": np.nan, "interval_low": np.nan,
                                "interval_high": np.nan, "seconds": np.nan,
                                "error": msg.replace("\n", " ")[:1000]})
                    row.update({c: np.nan for c in (*metric_columns(), *COUNT_COLUMNS, "review")})
                    # the truth's side is known: a failure's precision / recall is scored where it has points
                    row.update({k: v for k, v in point_counts((), (), truth).items() if k.endswith("_true_n")})
                else:
                    metrics = segment_metrics(est.coverage, est.holes, est.centerline, truth)
                    low, high = est.coverage_interval if est.coverage_interval is not None else (np.nan, np.nan)
                    row.update({"coverage": est.coverage, "interval_low": low, "interval_high": high,
                                "review": est.review_count, **metrics,
                                **point_counts(est.holes, est.centerline, truth), "seconds": seconds, "error": ""})
                    if i in examples and len(getattr(est, "mesh_faces", ())):
                        stem = shard_name.replace("/", "_").removesuffix(".h5")
                        save_example(Path(run_dir) / "examples" / m.name / f"{stem}-{i:03d}-noise{sigma:g}.npz",
                                      pts, est, truth)
                out[m.name].append(row)
    return out


# ---------------------------------------------------------------------------------------------- the run


def _unit_key(shard_name: str, sigma: float) -> str:
    return f"{shard_name.replace('/', '_').removesuffix('.h5')}__noise{sigma:g}"


def _finalize(out: Path, run: dict, name: str, keys: list[str]) -> Path:
    df = with_sample_ids(pd.concat([read_rows(out / "parts" / name / f"{k}.csv") for k in keys], ignore_index=True))
    write_csv(out / "results" / f"{name}.csv", df)
    rec = run["methods"][name]
    summary = {"method": name, **rec, "data": run["data"], "suite": run.get("suite"), "track": tracks.of_run(run),
               "noise_mm": run["noise_mm"], "noise_seed": run["noise_seed"], "thresholds_mm": run["thresholds_mm"],
               "versions": run["versions"], "summary": summarize(df).to_dict("records")}
    write_json(out / "results" / f"{name}.json", summary)
    return out / "results" / f"{name}.csv"


def checked_arguments(workers: int, noise, methods) -> tuple[list[float], list]:
    """The sorted noise sigmas and the methods (specs or objects) of a run, or an :class:`InputError`."""
    if workers < 1:
        raise InputError(f"--workers must be >= 1, got {workers}")
    sigmas = sorted({float(s) for s in noise})
    if not sigmas or any(s < 0 or not np.isfinite(s) for s in sigmas):
        raise InputError(f"noise levels must be non-negative mm, got {list(noise)}")
    specs = method_list(methods)
    if not specs:
        raise InputError("no methods given")
    return sigmas, specs


def method_list(methods) -> list:
    """Methods as a list: one spec or object, or several; specs stripped, empty ones left out."""
    if isinstance(methods, str) or not isinstance(methods, (list, tuple)):
        methods = [methods]
    return [m.strip() if isinstance(m, str) else m for m in methods if not isinstance(m, str) or m.strip()]


def load_methods(specs: list, options: dict, refuse_truth: str | None = None) -> dict:
    """``{name: (spec, method)}`` of specs (names, ``module:Class``, ``exec:...``) or method objects (their spec
    None); two methods of one name, or (with ``refuse_truth``, the reason) a method given ground truth, are
    refused."""
    from colonbench.benchmark.registry import as_method

    loaded = {}
    for spec in specs:
        if isinstance(spec, str):
            m = load_method(spec, **options)
        else:
            m, spec = as_method(spec), None
        if refuse_truth and getattr(m, "uses_truth", False):
            raise InputError(f"method {m.name!r} is given ground truth per segment; {refuse_truth}")
        if m.name in loaded:
            raise InputError(f"two methods are named {m.name!r}; rename one")
        loaded[m.name] = (spec, m)
    return loaded


def suite_of(identity: dict, sigmas, noise_seed: int, task: str, data, allow_unverified: bool) -> dict | None:
    """The record of the suite a run's data and protocol are (checked against its published signature), or None."""
    from colonbench.benchmark import suites

    suite = suites.match(identity, sigmas, noise_seed, task, data)
    return suites.verify(suite, data, allow_unverified) if suite is not None else None


def evaluate(data, methods, out, noise=(0.0, 0.5), split: str = "test", limit: int | None = None,
             workers: int = 1, model=None, device: str = "cpu", examples: int = 3, noise_seed: int = 0,
             progress: bool = True, scheduler=None, allow_unverified: bool = False, timeout: float | None = None,
             batch: int | None = None, tta: int = 1, retry_failed: bool = False, track: str = tracks.DEFAULT) -> Path:
    """Evaluate methods on a dataset split; write (or finish) a run folder.

    Parameters
    ----------
    data : path
        Dataset folder (``colonbench generate``).
    methods : list of str or method objects
        Registered names, ``module:Class``, ``exec:PROGRAM ARGS`` or ``predictions:DIR`` specs
        (:mod:`colonbench.benchmark.registry`), or objects with ``name`` and ``estimate(points)``
        (:class:`colonbench.estimate.Method`; they run in this process).
    out : path
        Run folder.
    noise : sequence of float
        Gaussian noise sigmas added to the inputs, mm.
    split : str
    limit : int, optional
        Only this many samples, spread evenly over the split.
    workers : int
        Processes (each loads the methods once and uses one torch thread); ``exec:`` programs run this many
        calls at a time.
    model, device
        Passed to methods that take them (default: the shipped model, CPU).
    examples : int
        Segments whose completed meshes are kept for the Fig. 5 triplets.
    noise_seed : int
        Root seed of the input noise.
    progress : bool
    scheduler : str or distributed.Client, optional
        Run the units on a Dask cluster (:func:`colonbench.benchmark.parallel.run_units`).
    allow_unverified : bool
        Evaluate data that is a suite's by name and protocol but not by its published content hash (the run
        then records ``verified: false``).
    timeout, batch
        ``exec:`` methods: seconds per input, inputs per call.
    tta : int
        Passed to the methods on the network that take it: their prediction averaged over this many symmetries
        of the grid (:mod:`colonbench.completion.symmetry`; default 1, the network once).
    retry_failed : bool
        Evaluate again, in the same run folder, the segments whose rows hold an error (an ``exec:`` program's
        answers and notes on them are removed first, so that it runs on them again); the other rows are kept.
    track : str
        ``points`` or ``length``: the methods that take it are given each segment's length (:mod:`.tracks`).

    Returns
    -------
    Path
        The run folder.

    Raises
    ------
    InputError
        Bad arguments, or data that claims to be a suite and is not (see ``allow_unverified``).
    """
    data, out = Path(data), Path(out)
    track = tracks.check(track)
    sigmas, specs = checked_arguments(workers, noise, methods)
    identity, picks = select(data, split, limit)
    suite = suite_of(identity, sigmas, noise_seed, "segments", data, allow_unverified)
    options = {"model": str(model) if model is not None else None, "device": device, "tta": check_tta(tta),
               "predictions": str(out / "predictions"), "timeout": timeout, "batch": batch}
    t0 = time.perf_counter()
    loaded = load_methods(specs, options)
    settings = {"data": identity, "suite": suite, "track": track, "noise_mm": sigmas, "noise_seed": int(noise_seed),
                "thresholds_mm": list(THRESHOLDS_MM)}
    check_run_folder(out)
    with folder_lock(out, "evaluate", "evaluation"):
        run = begin_run(out, settings, loaded, data)
        return _run(out, run, data, picks, sigmas, loaded, options, workers, examples, noise_seed, progress, t0,
                    scheduler, retry_failed, track)


def _run_programs(out, data, units, loaded, noise_seed, workers, progress, track=tracks.DEFAULT) -> None:
    """Run every ``exec:`` method's program on the inputs its unfinished units need, in batches across units (on
    the known-length track with each input's length: one call per length and batch)."""
    from colonbench.benchmark.external import ExecMethod
    from colonbench.progress import bar as progress_bar
    from colonbench.shards.reader import Shard

    for name, (_, m) in loaded.items():
        if not isinstance(m, ExecMethod):
            continue
        items = []
        for shard_name, indices, sigma, todo, *_ in units:
            ids = {sample_id(shard_name, i, sigma): i for i in indices} if name in todo else {}
            pending = m.missing(ids)
            if pending:
                with Shard(Path(data) / shard_name) as shard:  # opened once for its samples
                    for sid in pending:
                        geo = shard.geometry(ids[sid])
                        items.append((sid, noisy(geo["partial_points"], sigma, noise_seed, shard_name, ids[sid]),
                                      float(geo["length_mm"]) if track == "length" else None))
        if items:
            with progress_bar(total=len(items), unit="input", desc=f"run {name}", enabled=progress) as bar:
                m.run(items, workers=workers, progress=bar.update)


def _retry_units(out: Path, picks, sigmas, loaded) -> list:
    """Units of the failed segments of a run's finished parts, one per part with failures: ``(shard, failed
    indices, sigma, [method], [], key)``; an ``exec:`` method forgets its answers on them, so that it runs again."""
    from colonbench.benchmark.external import ExecMethod

    units = []
    for shard_name, _ in picks:
        for s in sigmas:
            key = _unit_key(shard_name, s)
            for name, (_, m) in loaded.items():
                part = out / "parts" / name / f"{key}.csv"
                if not part.exists():
                    continue
                rows = read_rows(part)
                again = [int(i) for i in rows.loc[rows["error"] != "", "index"]]
                if again:
                    units.append((shard_name, again, s, [name], [], key))
                    if isinstance(m, ExecMethod):
                        m.forget(sample_id(shard_name, i, s) for i in again)
    return units


def _warn_kept_failures(out: Path, keys, loaded) -> None:
    """Warn, per method, how many failed rows of its parts an earlier run stored that this one keeps as they are."""
    for name in loaded:
        parts = [out / "parts" / name / f"{key}.csv" for key in keys]
        kept = sum(int((read_rows(p)["error"] != "").sum()) for p in parts if p.exists())
        if kept:
            logging.getLogger(__name__).warning("colonbench: warning: %s: %d stored failure(s) of an earlier run in "
                                                "%s kept, not evaluated again (--retry-failed evaluates them again)",
                                                name, kept, out)


def _run(out, run, data, picks, sigmas, loaded, options, workers, examples, noise_seed, progress, t0,
         scheduler=None, retry_failed: bool = False, track: str = tracks.DEFAULT) -> Path:
    flat = [(n, i) for n, idx in picks for i in idx]
    ex_keys = {flat[k] for k in np.unique(np.linspace(0, len(flat) - 1, examples).astype(int))} if examples else set()
    units, keys = [], []
    for shard_name, idx in picks:
        for s in sigmas:
            key = _unit_key(shard_name, s)
            keys.append(key)
            todo = [n for n in loaded if not (out / "parts" / n / f"{key}.csv").exists()]
            if todo:
                ex = [i for i in idx if (shard_name, i) in ex_keys]
                units.append((shard_name, idx, s, todo, ex, key))
    if retry_failed:
        units += _retry_units(out, picks, sigmas, loaded)
    else:
        _warn_kept_failures(out, keys, loaded)
    _run_programs(out, data, units, loaded, noise_seed, workers, progress, track)
    from colonbench.progress import bar as progress_bar

    total = sum(len(u[1]) for u in units)
    bar = progress_bar(total=total, unit="segment", desc="evaluate", enabled=progress)
    args = lambda u: (str(data), u[0], u[1], u[2], noise_seed, u[3], u[4], str(out), track)  # noqa: E731
    try:
        for u, rows in run_units(run_unit, units, args, loaded, options, workers, scheduler):
            _store(out, u, rows)
            bar.update(len(u[1]))
    finally:
        bar.close()
    from colonbench.benchmark.external import ExecMethod

    for name, (_, m) in loaded.items():
        if isinstance(m, ExecMethod):   # where its seconds come from (docs/formats.md)
            run["methods"][name]["seconds_from"] = m.seconds_from(
                sample_id(n, i, s) for n, idx in picks for i in idx for s in sigmas)
        _finalize(out, run, name, keys)
    wall = time.perf_counter() - t0
    peak = max(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss,
               resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss) / 1024
    run["sessions"].append({"segments": total, "wall_seconds": round(wall, 1), "workers": workers,
                            "scheduler": None if scheduler is None else str(scheduler),
                            "peak_process_mib": round(peak), "finished": time.strftime("%Y-%m-%dT%H:%M:%S")})
    run["complete"] = True
    write_json(out / RUN_FILE, run)
    return out


def _store(out: Path, unit, rows: dict):
    """Write a unit's rows into its parts; into a part that exists (a retry of its failed segments), in place of
    the rows of the same samples."""
    key = unit[5]
    for name, r in rows.items():
        path = out / "parts" / name / f"{key}.csv"
        new = pd.DataFrame(r, columns=result_columns())
        if path.exists():
            old = read_rows(path)
            new = pd.concat([old[~old["index"].isin(new["index"])], new], ignore_index=True)
            new = new.sort_values("index", kind="stable").reset_index(drop=True)
        write_csv(path, new.reindex(columns=result_columns()))


def load_results(run_dir) -> tuple[dict, pd.DataFrame]:
    """A finished run: its record and every per-segment row of every method.

    Raises
    ------
    InputError
        Not a run, or a run with methods whose results are not all there.
    """
    run_dir = Path(run_dir)
    run = read_run(run_dir)
    if run.get("task") == "colon":
        raise InputError(f"{run_dir}: a whole-colon run; read it with colonbench.benchmark.colon_evaluate")
    frames = []
    for name in run["methods"]:
        csv = run_dir / "results" / f"{name}.csv"
        if not csv.is_file():
            raise InputError(f"{run_dir}: method {name!r} is not finished; rerun colonbench evaluate into it")
        df = with_sample_ids(read_rows(csv))
        expected = run["data"]["samples"] * len(run["noise_mm"])
        if len(df) != expected:
            raise InputError(f"{csv}: {len(df)} rows, the run needs {expected}; rerun colonbench evaluate into it")
        frames.append(df)
    return run, pd.concat(frames, ignore_index=True)
