"""The whole-colon benchmark (``colonbench evaluate --task colon``): maps of whole reconstructions, scored exactly.

Each sample of a whole-colon dataset (``task: colon`` manifests,
:mod:`colonbench.shards.colonshard`) is one partial reconstruction of a whole
colon with its withdrawal trajectory. For every method, noise level and
*track* it is mapped with :func:`colonbench.mapping.colonmap.map_colon`
(60 mm segments by default) and scored with
:func:`colonbench.benchmark.colon_metrics.map_metrics` against the exact truth:

* each segment the map reports against the true coverage of the same region
  of the true surface (the faces whose true arc length lies between the true
  arc lengths at its two plane points);
* the whole-colon coverage against the observed share of the whole surface;
* the map's centerline by precision / recall at 2 mm.

Tracks: ``segment-only`` (context 0: each segment estimated on its own points,
the paper's protocol) and ``context-<M>mm`` (the segment's points plus its
neighbours' up to M mm beyond each plane, coverage counted between its planes).
Both tracks map the same reconstruction with the same centerline, so their
segments are the same and are compared one for one.

A run folder holds::

    run.json                              task "colon", data identity, noise, tracks, methods, versions
    parts/<method>/<unit>.segments.csv    per-segment rows of one sample at one noise level (resume points)
    parts/<method>/<unit>.colons.csv      its per-map rows
    results/segments.csv, colons.csv      every row of every method, once all parts exist
    examples/<unit>.pkl                   the first sample's truth and maps, for the figure

The noise is drawn as in the segment benchmark (stream ``("eval-noise", sigma in um, shard, index)``),
the same cloud for every method, track and rerun.
"""

from __future__ import annotations

import resource
import time
from pathlib import Path

import numpy as np
import pandas as pd

from colonbench.benchmark.colon_metrics import END_SEEN, map_metrics
from colonbench.benchmark.evaluate import checked_arguments, load_methods, noisy, select, suite_of
from colonbench.benchmark.exchange import sample_id
from colonbench.benchmark.parallel import run_units
from colonbench.benchmark.runfolder import RUN_FILE, begin_run, check_run_folder, read_rows, write_csv, write_json
from colonbench.completion.symmetry import check_tta
from colonbench.errors import ColonbenchError, InputError
from colonbench.estimate import review_count
from colonbench.folderlock import folder_lock
from colonbench.mapping import CONTEXT_MM, SEGMENT_MM

#: Default context margins of the tracks, mm: segment-only and ``colonbench map``'s default.
CONTEXTS_MM = (0.0, CONTEXT_MM)
#: The methods ``--methods all`` maps with: registry.DEFAULT_METHODS less those given ground truth (they cannot
#: map) and ``unwrap-pca`` (the segment benchmark's ablation of unwrap's centerline).
ALL_METHODS = ("completion", "thresholding", "unwrap", "poisson", "constant")
#: Per-segment columns of ``results/segments.csv``.
SEGMENT_COLUMNS = ["method", "track", "context_mm", "shard", "colon", "index", "hole_model", "noise_mm", "segment",
                   "piece", "start_mm", "end_mm", "true_start_mm", "true_end_mm", "points", "true_coverage",
                   "coverage", "coverage_error", "interval_low", "interval_high", "review", "area_mm2",
                   "true_area_mm2", "end_seen", "end_unobserved", "seconds", "error", "skipped"]
#: Per-map columns of ``results/colons.csv``.
COLON_COLUMNS = ["method", "track", "context_mm", "shard", "colon", "index", "hole_model", "noise_mm",
                 "colon_length_mm", "segments", "estimated", "interruptions", "true_coverage", "coverage",
                 "coverage_error", "segment_mae", "centerline_precision", "centerline_recall", "seconds", "error"]


def track_name(context_mm: float) -> str:
    """``segment-only`` for 0, ``context-<M>mm`` otherwise."""
    return "segment-only" if context_mm == 0 else f"context-{context_mm:g}mm"


_COLONS: dict = {}


def _colon(data: str, shard_name: str):
    """The shard and its colon's truth, kept for the next unit of the same shard in this process."""
    from colonbench.shards.colonshard import ColonShard

    key = (data, shard_name)
    if key not in _COLONS:
        _COLONS.clear()
        shard = ColonShard(Path(data) / shard_name)
        _COLONS[key] = (shard, shard.colon())
    return _COLONS[key]


def run_colon_unit(data: str, shard_name: str, index: int, sigma: float, noise_seed: int, names: list[str],
                   contexts: list[float], segment_mm: float, example: str | None = None,
                   methods: dict | None = None) -> dict:
    """Map and score one whole-colon sample at one noise level with the named methods, every track.

    Returns
    -------
    dict
        ``{method: (segment rows, colon rows)}`` (lists of dicts, :data:`SEGMENT_COLUMNS`, :data:`COLON_COLUMNS`).
    """
    from colonbench.mapping.reconstruction_centerline import colon_centerline
    from colonbench.mapping.colonmap import map_colon
    from colonbench.mapping.segments import whole_coverage

    shard, truth = _colon(data, shard_name)
    sample = shard.sample(index)
    points = noisy(sample["points"], sigma, noise_seed, shard_name, index)
    ids = {"shard": shard_name, "colon": shard.name, "index": index, "hole_model": sample["hole_model"],
           "noise_mm": sigma}
    out, examples = {}, {}
    t = time.perf_counter()
    try:
        pieces = colon_centerline(points, positions=sample["positions"])  # once for every method and track
    except ColonbenchError:
        pieces = None  # map_colon raises it again, per map
    centerline_s = time.perf_counter() - t
    external = [n for n in names if getattr(methods[n], "by_sample", False)]
    if external:  # methods answering by sample id: the segments' clouds, each under its id
        inputs = segment_inputs(points, sample["positions"], pieces, segment_mm, sample_id(shard_name, index, sigma))
        for n in external:
            bind_inputs(methods[n], inputs)
    for name in names:
        seg_rows, colon_rows = [], []
        for context in contexts:
            track = {"method": name, "track": track_name(context), "context_mm": context}
            t = time.perf_counter()
            try:
                result = map_colon(points, methods[name], segment_mm=segment_mm, positions=sample["positions"],
                                   progress=False, context_mm=context, pieces=pieces)
            except ColonbenchError as exc:
                colon_rows.append({**track, **ids, "colon_length_mm": float(shard.attrs["colon_length_mm"]),
                                   "true_coverage": sample["coverage"], "error": str(exc)})
                continue
            seconds = time.perf_counter() - t + centerline_s  # the shared centerline counted in every map
            segs = result["segments"]
            rows = [s.row() for s in segs]
            whole = whole_coverage(segs)
            score = map_metrics(rows, whole, result["centerline"], truth["vertices"], truth["faces"],
                                sample["observed_faces"], truth["centerline"], face_s=truth["face_arclength"])
            for k, (s, r) in enumerate(zip(segs, rows)):
                seen = score["end_seen"][k]
                low, high = s.coverage_interval or (np.nan, np.nan)   # the map's interval, where the method gives one
                seg_rows.append({**track, **ids, "segment": s.index, "piece": s.piece, "start_mm": r["start_mm"],
                                 "end_mm": r["end_mm"], "true_start_mm": score["true_start_mm"][k],
                                 "true_end_mm": score["true_end_mm"][k], "points": s.points,
                                 "true_coverage": score["segment_truth"][k], "coverage": r["coverage"],
                                 "coverage_error": score["segment_errors"][k], "interval_low": low,
                                 "interval_high": high, "area_mm2": r["area_mm2"],
                                 "true_area_mm2": score["true_area_mm2"][k], "end_seen": seen,
                                 "end_unobserved": bool(np.isfinite(seen) and seen < END_SEEN),
                                 "review": review_count(s.coverage_interval, s.review),
                                 "seconds": s.seconds, "error": s.error or "", "skipped": bool(s.skipped)})
            colon_rows.append({**track, **ids, "colon_length_mm": float(shard.attrs["colon_length_mm"]),
                               "segments": len(segs), "estimated": sum(s.coverage is not None for s in segs),
                               "interruptions": len(result["interruptions"]), "true_coverage": score["whole_truth"],
                               "coverage": whole, "coverage_error": score["whole_error"],
                               "segment_mae": score["segment_mae"],
                               "centerline_precision": score["centerline_precision"],
                               "centerline_recall": score["centerline_recall"], "seconds": seconds, "error": ""})
            if example is not None:
                examples[f"{name}|{track['track']}"] = (segs, score)
        out[name] = (seg_rows, colon_rows)
    if example is not None and examples:
        _save_example(Path(example), truth, sample, examples)
    return out


class _Recorder:
    """A stand-in method that keeps the clouds a map gives it."""

    name, version, completes_surface = "recorder", "-", False

    def __init__(self):
        self.clouds = []

    def estimate(self, points):
        from colonbench.estimate import Estimate

        self.clouds.append(np.asarray(points))
        return Estimate(0.5, None, None, self.name)


def segment_inputs(points, positions, pieces, segment_mm: float, sample: str) -> list[tuple[str, np.ndarray]]:
    """The cloud of every segment a whole-colon map estimates, under its id (``<sample>_seg<k>``).

    What a method that does not complete the surface is given in every track of the whole-colon benchmark
    (the segment's own points); ``colonbench export`` writes these for a whole-colon suite.

    Returns
    -------
    list of (str, (n, 3) float)
        Empty when no map can be made of the reconstruction.
    """
    from colonbench.benchmark.exchange import segment_id
    from colonbench.mapping.colonmap import MIN_POINTS, map_colon

    if pieces is None:
        return []
    rec = _Recorder()
    try:
        result = map_colon(points, rec, segment_mm=segment_mm, positions=positions, progress=False, context_mm=0.0,
                           pieces=pieces)
    except ColonbenchError:
        return []
    estimated = [s for s in result["segments"] if s.points >= MIN_POINTS]
    if len(estimated) != len(rec.clouds):
        raise ColonbenchError(f"{sample}: {len(rec.clouds)} clouds recorded for {len(estimated)} segments")
    return [(segment_id(sample, s.index), c) for s, c in zip(estimated, rec.clouds)]


def bind_inputs(method, inputs: list[tuple[str, np.ndarray]]) -> None:
    """Let a method answering by sample id find each segment's cloud; run an ``exec:`` program on those it lacks."""
    from colonbench.benchmark.external import ExecMethod, content_key

    if isinstance(method, ExecMethod):
        method.run(inputs)
    method.lookup = {content_key(p): sid for sid, p in inputs}


def _save_example(path: Path, truth: dict, sample: dict, maps: dict):
    """The truth and each map's segment meshes of one sample, for the figure
    (:func:`colonbench.reports.coverage_map.map_truth_error`)."""
    import pickle

    path.parent.mkdir(parents=True, exist_ok=True)
    keep = {"vertices": truth["vertices"].astype(np.float32), "faces": truth["faces"].astype(np.int32),
            "face_arclength": truth["face_arclength"].astype(np.float32),
            "observed": sample["observed_faces"], "maps": {}}
    for key, (segs, score) in maps.items():
        keep["maps"][key] = {"segments": [s.row() for s in segs], "meshes": [s.mesh for s in segs],
                             "truth": score["segment_truth"], "true_start_mm": score["true_start_mm"],
                             "true_end_mm": score["true_end_mm"]}
    tmp = path.with_name(f".{path.name}.tmp")
    with open(tmp, "wb") as fh:
        pickle.dump(keep, fh, protocol=4)
    tmp.replace(path)


def _unit_key(shard_name: str, index: int, sigma: float) -> str:
    return f"{Path(shard_name).with_suffix('').as_posix().replace('/', '__')}-{index}-noise{sigma:g}"


def evaluate_colons(data, methods, out, noise=(0.0, 0.5), contexts=CONTEXTS_MM, segment_mm: float = SEGMENT_MM,
                    split: str = "test", limit: int | None = None, workers: int = 1, model=None,
                    device: str = "cpu", noise_seed: int = 0, progress: bool = True, context_model=None,
                    scheduler=None, allow_unverified: bool = False, timeout: float | None = None,
                    batch: int | None = None, tta: int = 1) -> Path:
    """Map every whole-colon sample of a split with every method and track; write (or finish) a run folder.

    Parameters
    ----------
    data : path
        A whole-colon dataset folder (``colonbench generate`` on a ``task: colon`` manifest).
    methods : list of str
        Registered names or ``module:Class`` specs; methods given ground truth (references) cannot map.
    out : path
        Run folder.
    noise : sequence of float
        Gaussian noise sigmas added to the reconstructions, mm.
    contexts : sequence of float
        Context margins, one track each, mm (0 = segment-only).
    segment_mm : float
        Segment arc length, mm.
    split, limit, workers, model, device, noise_seed, progress, scheduler, allow_unverified, timeout, batch, tta
        As for :func:`colonbench.benchmark.evaluate.evaluate`; an ``exec:`` program is called once per map
        with the clouds of the segments it estimates.
    context_model : path or str, optional
        An in-context model for the tracks with context (methods that take one: ``completion``); the
        segment-only track keeps ``model``, the paper's protocol.

    Returns
    -------
    Path
        The run folder.
    """
    from colonbench.shards.colonshard import ColonShard

    data, out = Path(data), Path(out)
    sigmas, specs = checked_arguments(workers, noise, methods)
    contexts = sorted({float(c) for c in contexts})
    if not contexts or any(c < 0 or not np.isfinite(c) for c in contexts):
        raise InputError(f"context margins must be non-negative mm, got {list(contexts)}")
    if not segment_mm > 0:
        raise InputError(f"--segment-length must be positive, got {segment_mm}")
    identity, picks = select(data, split, limit)
    ColonShard(data / picks[0][0])  # a clear error for a segment dataset
    suite = suite_of(identity, sigmas, noise_seed, "colon", data, allow_unverified)
    options = {"model": str(model) if model is not None else None, "device": device, "tta": check_tta(tta),
               "context_model": str(context_model) if context_model is not None else None,
               "predictions": str(out / "predictions"), "timeout": timeout, "batch": batch}
    t0 = time.perf_counter()
    loaded = load_methods(specs, options, refuse_truth="it cannot map a whole reconstruction (the segment "
                                                       "benchmark's reference rows)")
    settings = {"task": "colon", "data": identity, "suite": suite, "noise_mm": sigmas, "noise_seed": int(noise_seed),
                "contexts_mm": contexts, "segment_mm": float(segment_mm), "thresholds_mm": [2.0]}
    check_run_folder(out)
    with folder_lock(out, "evaluate", "evaluation"):
        run = begin_run(out, settings, loaded, data)
        return _run(out, run, data, picks, sigmas, contexts, segment_mm, loaded, options, workers, noise_seed,
                    progress, t0, scheduler)


def _run(out, run, data, picks, sigmas, contexts, segment_mm, loaded, options, workers, noise_seed, progress,
         t0, scheduler=None) -> Path:
    from colonbench.progress import bar as progress_bar

    flat = [(n, i) for n, idx in picks for i in idx]
    units, keys = [], []
    for n, i in flat:
        for s in sigmas:
            key = _unit_key(n, i, s)
            keys.append(key)
            todo = [m for m in loaded if not (out / "parts" / m / f"{key}.colons.csv").exists()]
            if todo:
                example = str(out / "examples" / f"{key}.pkl") if (n, i) == flat[0] and s == sigmas[0] else None
                units.append((n, i, s, todo, example, key))
    bar = progress_bar(total=len(units), unit="map", desc="evaluate colons", enabled=progress)
    args = lambda u: (str(data), u[0], u[1], u[2], noise_seed, u[3], contexts, segment_mm, u[4])  # noqa: E731
    try:
        for u, rows in run_units(run_colon_unit, units, args, loaded, options, workers, scheduler):
            _store(out, u[5], rows)
            bar.update(1)
    finally:
        bar.close()
    for kind in ("segments", "colons"):
        frames = [read_rows(out / "parts" / m / f"{k}.{kind}.csv") for m in loaded for k in keys]
        write_csv(out / "results" / f"{kind}.csv", pd.concat(frames, ignore_index=True))
    wall = time.perf_counter() - t0
    peak = max(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss,
               resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss) / 1024
    run["sessions"].append({"maps": len(units) * len(contexts), "wall_seconds": round(wall, 1), "workers": workers,
                            "peak_process_mib": round(peak), "finished": time.strftime("%Y-%m-%dT%H:%M:%S")})
    run["complete"] = True
    write_json(out / RUN_FILE, run)
    return out


def _store(out: Path, key: str, rows: dict):
    for name, (seg_rows, colon_rows) in rows.items():
        write_csv(out / "parts" / name / f"{key}.segments.csv", pd.DataFrame(seg_rows, columns=SEGMENT_COLUMNS))
        write_csv(out / "parts" / name / f"{key}.colons.csv", pd.DataFrame(colon_rows, columns=COLON_COLUMNS))


def is_colon_run(run_dir) -> bool:
    """Whether a run folder holds a whole-colon run."""
    import json

    try:
        return json.loads((Path(run_dir) / RUN_FILE).read_text()).get("task") == "colon"
    except (OSError, ValueError):
        return False



def skipped_rows(segments: pd.DataFrame) -> np.ndarray:
    """(n,) bool: the segment rows the map gave no method (too few points, points beyond its centerline's reach):
    the ``skipped`` column, or where a row has none (written before it was recorded) what its ``error`` says
    (:func:`colonbench.mapping.segments.skipped_by_map`). Such a segment is no method's failure and is scored for
    none."""
    from colonbench.mapping.segments import skipped_by_map

    text = segments["error"].map(skipped_by_map).to_numpy(bool)
    if "skipped" not in segments.columns:
        return text
    flag = segments["skipped"]
    known = flag.notna() & flag.astype(str).str.strip().ne("")
    return np.where(known.to_numpy(), flag.astype(str).str.strip().str.lower().isin(["true", "1", "1.0"]).to_numpy(),
                    text)


def scoreable(segments: pd.DataFrame) -> pd.DataFrame:
    """Segment rows as every statistic scores them: a row the map gave no method (:func:`skipped_rows`) is no
    failure (its ``error`` blanked; its NaN error is left out), every other failed row is one
    (:func:`colonbench.benchmark.summary.scored_errors`)."""
    error = segments["error"].where(segments["error"].notna(), "").astype(str)
    return segments.assign(error=np.where(skipped_rows(segments), "", error))

def load_colon_results(run_dir) -> tuple[dict, pd.DataFrame, pd.DataFrame]:
    """A finished whole-colon run: its record, its per-segment rows and its per-map rows.

    Raises
    ------
    InputError
        Not a whole-colon run, or not finished.
    """
    import json

    run_dir = Path(run_dir)
    path = run_dir / RUN_FILE
    if not path.is_file():
        raise InputError(f"{run_dir}: not a colonbench run (no {RUN_FILE}); colonbench evaluate writes one")
    run = json.loads(path.read_text())
    if run.get("task") != "colon":
        raise InputError(f"{run_dir}: a segment run, not a whole-colon run (colonbench evaluate --task colon)")
    seg, col = run_dir / "results" / "segments.csv", run_dir / "results" / "colons.csv"
    if not (run.get("complete") and seg.is_file() and col.is_file()):
        raise InputError(f"{run_dir}: the run is not finished; rerun colonbench evaluate --task colon into it")
    colons = read_rows(col)
    expected = run["data"]["samples"] * len(run["noise_mm"]) * len(run["contexts_mm"]) * len(run["methods"])
    if len(colons) != expected:
        raise InputError(f"{col}: {len(colons)} rows, the run needs {expected}; rerun colonbench evaluate into it")
    return run, read_rows(seg), colons


def dataset_task(data) -> str:
    """``"colon"`` for a whole-colon dataset folder (``task: colon``), ``"segments"`` otherwise.

    Raises
    ------
    InputError
        Not a generated dataset folder.
    """
    from colonbench.shards.dataset import dataset_manifest
    from colonbench.shards.manifest import task

    return str(task(dataset_manifest(data)))
