"""The built-in methods' reference results on every suite, shipped with colonbench.

``benchmark/shipped_results/<suite id>/`` is a run folder without its working
files: ``run.json`` (suite, content hash, methods with their versions,
package versions, how long it took) and ``results/`` (segment suites:
``<method>.csv`` per segment and ``<method>.json`` summary; the whole-colon
suite: ``segments.csv`` and ``colons.csv``). ``colonbench benchmark`` merges
them into its leaderboards when their suite hash is the published one, so a
user runs only their own method; a method the user evaluates themselves
replaces its shipped rows.

The known-length track's (:mod:`colonbench.benchmark.tracks`) are beside
them in ``benchmark/shipped_results/<suite id>@length/``, merged only into
tables of that track. They are made by ``python scripts/reference_results.py``
(every built-in method on every suite and track, then :func:`publish`), never
edited by hand.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd

from colonbench.benchmark import tracks
from colonbench.benchmark.exchange import with_sample_ids
from colonbench.benchmark.metrics import THRESHOLDS_MM
from colonbench.benchmark.runfolder import RUN_FILE, read_rows, read_run, write_json
from colonbench.benchmark.verification import record_problems
from colonbench.errors import InputError

#: Where the shipped results live in the package.
SHIPPED_DIR = Path(__file__).resolve().parent / "shipped_results"
#: Significant digits kept of each float in a shipped CSV.
DIGITS = 10
#: Columns of a results row that reproduce on another machine to :data:`TOLERANCE` (fractions): another CPU's
#: float arithmetic moves the network's numbers by about 1e-9, the coverages they give by about 1e-8.
CONTINUOUS = ("true_coverage", "coverage", "coverage_error", "interval_low", "interval_high")
TOLERANCE = 1e-6
#: A coverage counts vertices or voxels: where one lies within float noise of the hole distance, another machine
#: puts it on the other side, and the coverage moves by its share of the surface (about 1e-4). Allowed: in at most
#: :data:`FLIPPED_ROWS` of the rows (at least one), a move of up to :data:`FLIPPED_STEP`. Measured with the eager
#: network in place of the one made fast for inference (their sums differ as two CPUs' do): one row of real-v1's 172
#: moved, by 8e-5 (completion) and 1e-4 (thresholding); none of demo-v1's 48.
FLIPPED_ROWS = 0.02
FLIPPED_STEP = 2e-3
#: What a method published from data within tolerance keeps of its run's suite record (:func:`publish`).
OWN_DATA = ("check", "bit_identical", "tie_samples", "redrawn_samples", "diverged_samples", "sha256")
#: Methods whose coverage no float noise moves measurably (docs/benchmark.md, Results on another machine).
EXACT = ("constant", "unwrap-pca", "unwrap-gt")
#: Points a threshold metric (a precision or recall: a share of points within 1 or 2 mm) or a point count may move
#: by on another machine: a point whose distance lies within float noise of the threshold falls on either side
#: (seen: one true hole point of 6,500 in demo-v1, 1.5e-4 of recall). Allowed: this many points of the count.
FLIPS = 3
#: Each threshold metric with the count of the points it is a share of.
SHARE_OF = {f"{what}_{pr}_{th:g}mm": f"{what}_n" if pr == "precision" else f"{what}_true_n"
            for th in THRESHOLDS_MM for what in ("holes", "centerline") for pr in ("precision", "recall")}


def folder(suite, track: str = tracks.DEFAULT) -> Path:
    """The shipped results folder of a suite on a track: ``<suite id>`` (points), ``<suite id>@length``."""
    track = tracks.check(track)
    return SHIPPED_DIR / (suite.id if track == tracks.DEFAULT else f"{suite.id}@{track}")


def record(suite, track: str = tracks.DEFAULT) -> dict | None:
    """The ``run.json`` of a suite's shipped results on a track; None when there are none, or when they were made on
    other data than the published suite (another hash) or on another track."""
    where = folder(suite, track)
    if not (where / RUN_FILE).is_file():
        return None
    run = read_run(where)
    if (run.get("suite") or {}).get("sha256") != suite.sha256 or tracks.of_run(run) != track:
        return None
    return run


def load(suite, exclude=(), track: str = tracks.DEFAULT) -> tuple | None:
    """The shipped results of a suite on a track as a loaded run, less the methods in ``exclude``; None when there
    are none, or when they were made on other data than the published suite (another hash) or on another track.

    Returns
    -------
    tuple or None
        Segment suites ``(run record, results, label)``; whole colons ``(run record, segments, colons, label)``
        (:func:`colonbench.reports.leaderboard.merge_runs` and ``merge_colon_runs`` take them).
    """
    where = folder(suite, track)
    run = record(suite, track)
    if run is None:
        return None
    rec = run["suite"]
    if "signature" not in rec:   # made on the published data itself (its hash), before suites had signatures
        run["suite"] = {**rec, "signature": suite.signature, "check": "bit-identical", "bit_identical": True,
                        "tie_samples": 0}
    methods = {n: r for n, r in run["methods"].items() if n not in set(exclude)}
    if not methods:
        return None
    run = {**run, "methods": methods}
    label = f"shipped {suite.id}" + ("" if track == tracks.DEFAULT else f"@{track}")
    if run.get("task") == "colon":
        segs = read_rows(where / "results" / "segments.csv")
        cols = read_rows(where / "results" / "colons.csv")
        return run, segs[segs["method"].isin(methods)], cols[cols["method"].isin(methods)], label
    frames = [read_rows(where / "results" / f"{n}.csv") for n in methods]
    return run, with_sample_ids(pd.concat(frames, ignore_index=True)), label


def publish(run_dir, suite, methods=None, track: str | None = None) -> Path:
    """Copy a finished run of a suite into the shipped results of its track (:func:`folder`): all of it (replacing
    what was there), or only ``methods``, whose rows replace their shipped ones while the other methods' stay.

    Some ``methods`` may come from a run whose data verified within tolerance of the published data (decision record
    0327): each keeps its own suite record (``methods.<name>.suite`` in ``run.json``: the check, the samples decided
    otherwise, the content hash of its data), and the run's record stays that of the data the other rows came from.
    The whole run is published only from the published data themselves (bit-identical).

    Raises
    ------
    InputError
        The run is not of this suite, its data did not verify against the suite's published signature (or, for the
        whole run, are not bit-identical to the published data), it is not of ``track`` (where given), not finished,
        or lacks a method asked for.
    """
    run_dir = Path(run_dir)
    run = read_run(run_dir)
    if track is not None and tracks.check(track) != tracks.of_run(run):
        raise InputError(f"{run_dir}: a run of the {tracks.label(tracks.of_run(run))}, not the "
                         f"{tracks.label(track)}")
    track = tracks.of_run(run)
    rec = run.get("suite") or {}
    exact = rec.get("sha256") == suite.sha256
    near = (methods is not None and suite.task != "colon" and rec.get("check") == "within tolerance"
            and not record_problems(rec, suite))
    if rec.get("id") != suite.id or not rec.get("verified") or not (exact or near):
        raise InputError(f"{run_dir}: not a run of {suite.id} on its published data (bit-identical"
                         f"{', or within tolerance of its signature' if methods and suite.task != 'colon' else ''}; "
                         f"its suite record: {rec or 'none'})")
    if not run.get("complete"):
        raise InputError(f"{run_dir}: not finished")
    if methods is not None:
        missing = sorted(set(methods) - set(run["methods"]))
        if missing:
            raise InputError(f"{run_dir}: holds no run of {', '.join(missing)}")
        there = folder(suite, track)
        if (there / RUN_FILE).is_file():
            old = read_run(there)
            if (old.get("suite") or {}).get("sha256") != suite.sha256:
                raise InputError(f"{there}: its shipped results were not made on {suite.id}'s published data: "
                                 "publish a whole run made on them first")
        elif exact:
            old = {**run, "methods": {}}
        else:
            raise InputError(f"{run_dir}: its data are within tolerance of {suite.id}'s, and there are no shipped "
                             f"results made on the published data to add its rows to ({there})")
        # each re-published method keeps the versions and machine it ran with
        # and the data it ran on, where they are not the run's own (0327)
        fresh = {m: {**run["methods"][m], "versions": run.get("versions"), "environment": run.get("environment")}
                 for m in methods}
        if not exact:
            for m in methods:
                fresh[m]["suite"] = {k: rec[k] for k in OWN_DATA if k in rec}
        run = {**old, "methods": {**old["methods"], **fresh}, "suite": old["suite"]}
    return write_results(run_dir, run, folder(suite, track), methods)


def write_results(run_dir, run: dict, out, methods=None) -> Path:
    """Write a run's record and result files into ``out`` as shipped results are kept (``run.json`` without its
    ``data_path``; ``results/`` with each float to :data:`DIGITS` significant digits), written aside and put in place
    whole. Every method of ``run["methods"]`` comes from ``run_dir``, or where ``methods`` is given only those, the
    others from what ``out`` held (:func:`publish` of some methods; a submitted result:
    :mod:`colonbench.benchmark.submitted`).

    Returns
    -------
    Path
        ``out``.
    """
    run_dir, out = Path(run_dir), Path(out)
    colon = run.get("task") == "colon"
    staging = out.with_name(f".{out.name}.new")
    shutil.rmtree(staging, ignore_errors=True)
    (staging / "results").mkdir(parents=True)
    names = ["segments.csv", "colons.csv"] if colon else \
        [f"{n}.{ext}" for n in run["methods"] for ext in ("csv", "json")]
    for name in names:
        src = run_dir / "results" / name
        if methods is not None and (colon or Path(name).stem not in methods):
            src = out / "results" / name              # kept from the shipped results
        if name.endswith(".csv"):
            rows = read_rows(src)
            if colon and methods is not None:         # the new run's rows of these methods, the shipped ones of others
                new = read_rows(run_dir / "results" / name)
                rows = pd.concat([rows[~rows["method"].isin(methods)], new[new["method"].isin(methods)]],
                                 ignore_index=True)
            rows.to_csv(staging / "results" / name, index=False, float_format=f"%.{DIGITS}g")
        else:
            summary = json.loads(src.read_text())
            summary.pop("data_path", None)
            write_json(staging / "results" / name, summary)
    write_json(staging / RUN_FILE, {k: v for k, v in run.items() if k != "data_path"})
    shutil.rmtree(out, ignore_errors=True)
    staging.rename(out)
    return out


def differences(ours: pd.DataFrame, reference: pd.DataFrame, flips: int = FLIPS,
                tolerance: float = TOLERANCE, counted: bool = True) -> pd.DataFrame:
    """Where rows of a method differ from its reference rows (its shipped ones) by more than a reproduction on
    another machine may: a continuous column (:data:`CONTINUOUS`) by more than ``tolerance`` (a coverage, in a few rows,
    by up to :data:`FLIPPED_STEP`), a point count by
    more than ``flips``, a threshold metric by more than ``flips`` points of its count (:data:`SHARE_OF`; the
    count of ``ours``, or of ``reference`` where larger), or a value defined on one side only.

    Parameters
    ----------
    ours, reference : DataFrame
        Results rows (:func:`colonbench.benchmark.evaluate.result_columns`) of one method on the same segments,
        keyed by ``shard``, ``index`` and ``noise_mm``; rows made before the counts existed compare their threshold
        metrics with the counts of the other side (neither side's: to ``tolerance``).
    counted : bool
        Whether the method's coverage counts vertices, voxels or cells that float noise can move (the methods on
        the network): then a few rows may move by up to :data:`FLIPPED_STEP`; else (:data:`EXACT`) none.

    Returns
    -------
    DataFrame
        One row per differing cell: the key, ``column``, ``ours``, ``reference``, ``allowed``; empty when the rows
        reproduce. Raises ``ValueError`` where the two do not hold the same segments.
    """
    key = ["shard", "index", "noise_mm"]
    a, b = ours.set_index(key).sort_index(), reference.set_index(key).sort_index()
    if not a.index.equals(b.index):
        raise ValueError(f"the rows hold other segments: {len(a.index.difference(b.index))} only in ours, "
                         f"{len(b.index.difference(a.index))} only in the reference")
    out = []

    def count(col):
        n = [t[col].to_numpy(float) for t in (a, b) if col in t.columns]
        return np.fmax.reduce(n) if n else np.full(len(a), np.nan)

    allowed = {c: np.full(len(a), tolerance) for c in CONTINUOUS}
    allowed.update({c: np.full(len(a), float(flips)) for c in set(SHARE_OF.values())})
    allowed.update({c: np.where(np.isfinite(count(n)), flips / np.maximum(count(n), 1.0) + 1e-12, tolerance)
                    for c, n in SHARE_OF.items()})          # no count on either side: float noise only
    spare = max(1, int(FLIPPED_ROWS * len(a)))
    for col, bound in allowed.items():
        if col not in a.columns or col not in b.columns:
            continue
        x, y = a[col].to_numpy(float), b[col].to_numpy(float)
        bad = (np.isnan(x) != np.isnan(y)) | (np.abs(x - y) > bound + tolerance * np.abs(y))
        if counted and col in CONTINUOUS and col != "true_coverage":   # a few rows may move by a vertex's share
            flipped = bad & (np.abs(x - y) <= FLIPPED_STEP)
            if flipped.sum() <= spare and not (bad & ~flipped).any():
                bad[:] = False
        for k in np.flatnonzero(bad):
            out.append({**dict(zip(key, a.index[k])), "column": col, "ours": x[k], "reference": y[k],
                        "allowed": bound[k]})
    return pd.DataFrame(out, columns=[*key, "column", "ours", "reference", "allowed"])


def reproduction(run_dir, suite, methods, track: str = tracks.DEFAULT) -> dict:
    """How a run of a segment suite compares with the shipped rows of the same methods, as another machine may
    differ (:func:`differences`; :data:`EXACT` methods with no flipped row).

    Parameters
    ----------
    run_dir : path
        A finished run of ``suite`` on ``track`` holding ``results/<method>.csv`` for every method.
    methods : list of str
        Methods to compare; each must have shipped rows.

    Returns
    -------
    dict
        ``{method: DataFrame}``, the differing cells of each method (empty where it reproduces).
    """
    item = load(suite, track=track)
    if item is None or item[0].get("task") == "colon":
        raise InputError(f"{suite.id}: no shipped rows of a segment suite on the {tracks.label(track)} to compare with")
    rows = item[1]
    out = {}
    for m in methods:
        ref = rows[rows["method"] == m]
        if ref.empty:
            raise InputError(f"{suite.id}: no shipped rows of {m}")
        ours = read_rows(Path(run_dir) / "results" / f"{m}.csv")
        out[m] = differences(ours, ref, counted=m not in EXACT)
    return out


def own_data(suite, method: str, track: str = tracks.DEFAULT) -> dict | None:
    """The suite record of the data a shipped method's rows were made on, where they are not the published data
    (:func:`publish` from data within tolerance); None where they are, or where the method has no shipped rows."""
    run = record(suite, track)
    own = (run["methods"].get(method) or {}).get("suite") if run else None
    return None if not own or own.get("bit_identical") else own


def shipped_items(suite, exclude=(), track: str = tracks.DEFAULT) -> list:
    """The shipped results of ``suite`` on ``track`` as extra runs for a leaderboard (an empty list when there are
    none)."""
    item = load(suite, exclude, track)
    return [item] if item is not None else []
