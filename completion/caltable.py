"""The interval calibration's table of estimates: ``<model stem>.calibration-estimates-<sha>-<steps>.csv`` beside the
model (``sha``: the model file's sha256, its first 12 hex digits; ``steps``: the method's steps, ``steps=10``), with
what it was made of in a JSON file of the same name (:func:`made_of_path`).

``scripts/calibrate_intervals.py`` estimates every segment of the calibration's datasets and writes the estimates and
their signals here, one row per segment and noise level; it then calibrates on the table as read back (decision
record 0178). Another machine generates some of the datasets' samples otherwise (a near-tie decided the other way,
points redrawn on the same surface) and estimates in other last bits, and the calibration's rules cross near-ties
downstream; calibrated on the same table, the calibration file is the same wherever it is made. :func:`compare` tells
how a table made again differs from another.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from colonbench.completion.modelfile import beside
from colonbench.errors import InputError
from colonbench.shards.schema import sha256_file

#: The columns that name a row: its dataset (manifest name), shard, sample and noise level (mm).
KEY = ("manifest", "shard", "index", "noise_mm")
#: The columns every table holds besides its signals.
COLUMNS = KEY + ("colon_id", "hole_model", "segment_mm", "true", "estimate")
#: How far an estimate may move before :func:`compare` counts it (fractions of coverage): a last-bit move, and a point.
MOVES = (1e-6, 0.01)
#: How far a row's true coverage may move before :func:`compare` counts its sample as generated otherwise: float noise
#: moves it by about 1e-15, a near-tie decided the other way or points redrawn by far more.
TRUTH_MOVE = 1e-9


def path_for(model: Path, steps: str) -> Path:
    """The table of a model file (its path) and the method's steps (``steps=10``), beside the model: another model
    at the same path, or other steps, have a table of their own."""
    return beside(model, f".calibration-estimates-{sha256_file(model)[:12]}-{steps}.csv")


def made_of_path(path: Path) -> Path:
    """The JSON file beside a table that says what it was made of (``<table stem>.json``)."""
    return Path(path).with_suffix(".json")


def write(table: pd.DataFrame, path: Path, made_of: dict) -> None:
    """Write a table and what it was made of.

    Parameters
    ----------
    table : pandas.DataFrame
        :data:`COLUMNS` and the signals, one row per segment and noise level, in the order to keep.
    path : Path
        The CSV file; every float is written as Python's shortest repr, so that :func:`read` gives back the same
        values.
    made_of : dict
        What the table was made of (JSON-serialisable: the model's and the manifests' sha256, the steps, the
        signals), written to :func:`made_of_path`; :func:`read` checks it.
    """
    missing = [c for c in COLUMNS if c not in table.columns]
    if missing:
        raise ValueError(f"a table of calibration estimates needs the columns {', '.join(missing)}")
    table.to_csv(path, index=False, lineterminator="\n")
    made_of_path(path).write_text(json.dumps(made_of, indent=1, sort_keys=True) + "\n")


def read(path: Path, signals=(), made_of: dict | None = None) -> pd.DataFrame:
    """A table of calibration estimates, every float as written (:func:`write`).

    Parameters
    ----------
    path : Path
        The CSV file.
    signals : sequence of str
        The signal columns the caller calibrates with; each must be there.
    made_of : dict, optional
        What the table must have been made of; where given, the JSON file beside the table (:func:`made_of_path`)
        must say the same.

    Returns
    -------
    pandas.DataFrame
        One row per segment and noise level, in the file's order.

    Raises
    ------
    InputError
        Where the file cannot be read as a CSV table, has no rows, lacks a column, repeats a row's key, holds an
        estimate or truth that is not a coverage (a number in [0, 1]), or was made of something else than
        ``made_of`` says.
    """
    if made_of is not None:
        try:
            recorded = json.loads(made_of_path(path).read_text())
        except (OSError, ValueError) as exc:
            raise InputError(f"{path}: what it was made of is unknown ({made_of_path(path).name}: {exc}); make it "
                             "again (scripts/calibrate_intervals.py --remake)") from None
        if recorded != made_of:
            differ = sorted(k for k in set(recorded) | set(made_of) if recorded.get(k) != made_of.get(k))
            raise InputError(f"{path}: made of another {', '.join(differ)} than now; make it again "
                             "(scripts/calibrate_intervals.py --remake)")
    try:
        table = pd.read_csv(path)
    except (OSError, ValueError, pd.errors.ParserError) as exc:
        raise InputError(f"{path}: not a table of calibration estimates ({exc})") from None
    if table.empty:
        raise InputError(f"{path}: a table of calibration estimates with no rows")
    missing = [c for c in (*COLUMNS, *signals) if c not in table.columns]
    if missing:
        raise InputError(f"{path}: lacks the columns {', '.join(missing)} (made by an older scripts/"
                         "calibrate_intervals.py? make it again with --remake)")
    repeated = int(table.duplicated(list(KEY)).sum())
    if repeated:
        raise InputError(f"{path}: {repeated} rows repeat a (manifest, shard, index, noise_mm) already there")
    values = table[["true", "estimate"]].apply(pd.to_numeric, errors="coerce").to_numpy(float)
    if not (np.isfinite(values).all() and (values >= 0).all() and (values <= 1).all()):
        raise InputError(f"{path}: every true and estimated coverage must be a fraction in [0, 1]")
    return table


def compare(old: pd.DataFrame, new: pd.DataFrame) -> dict:
    """How a table made again (``new``) differs from another (``old``), row by row on :data:`KEY`.

    Parameters
    ----------
    old, new : pandas.DataFrame
        Tables of calibration estimates (:func:`read`; ``new`` may be one not yet written).

    Returns
    -------
    dict
        ``rows`` (both), ``only_old``, ``only_new`` (rows in one of them), ``truths`` (rows whose true coverage
        moved by more than :data:`TRUTH_MOVE`: their samples were generated otherwise, so the data differ from those
        ``old`` was made of), ``moved`` (estimates moved by more than each of :data:`MOVES`, keyed by the move as
        written, ``"1e-06"`` and ``"0.01"``), ``largest`` (the largest move, a fraction) and ``rims`` (rows whose
        count of cut rims differs, where both tables have it).
    """
    both = old.merge(new, on=list(KEY), how="outer", suffixes=("_old", "_new"), indicator=True)
    matched = both[both["_merge"] == "both"]
    move = (matched["estimate_new"] - matched["estimate_old"]).abs()
    out = {"rows": int(len(matched)), "only_old": int((both["_merge"] == "left_only").sum()),
           "only_new": int((both["_merge"] == "right_only").sum()),
           "truths": int(((matched["true_new"] - matched["true_old"]).abs() > TRUTH_MOVE).sum()),
           "moved": {f"{m:g}": int((move > m).sum()) for m in MOVES},
           "largest": float(move.max()) if len(move) else 0.0}
    if "rims_old" in matched and "rims_new" in matched:
        out["rims"] = int((matched["rims_old"] != matched["rims_new"]).sum())
    return out
