"""The interval calibration's table of estimates: ``<model stem>.calibration-estimates-<sha>-<steps>.csv`` beside the
model (``sha``: the model file's sha256, its first 12 hex digits; ``steps``: the method's steps, ``steps=10``).

``scripts/calibrate_intervals.py`` estimates every segment of the calibration's datasets and writes the estimates and
their signals here, one row per segment and noise level; it then calibrates on the table as read back (decision
record 0178). An estimate differs in its last bits from one machine to another (other BLAS and PyTorch kernels), and
the calibration's rules cross near-ties downstream; calibrated on the same table, the calibration file is the same on
every machine. :func:`compare` tells how a table made again differs from the committed one.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from colonbench.errors import InputError
from colonbench.shards.schema import sha256_file

#: The columns that name a row: its dataset (manifest name), shard, sample and noise level (mm).
KEY = ("manifest", "shard", "index", "noise_mm")
#: The columns every table holds besides its signals.
COLUMNS = KEY + ("colon_id", "hole_model", "segment_mm", "true", "estimate")
#: How far an estimate may move before :func:`compare` counts it (fractions of coverage): a last-bit move, and a point.
MOVES = (1e-6, 0.01)


def path_for(model: Path, steps: str) -> Path:
    """The table of a model file and the method's steps (``steps=10``) beside it: another model at the same path, or
    other steps, have a table of their own."""
    model = Path(model)
    return model.with_name(f"{model.name.removesuffix('.safetensors')}.calibration-estimates-"
                           f"{sha256_file(model)[:12]}-{steps}.csv")


def write(table: pd.DataFrame, path: Path) -> None:
    """Write a table (:data:`COLUMNS` and signals, in its own row order), every float as Python's shortest repr, so
    that :func:`read` gives back the same values."""
    missing = [c for c in COLUMNS if c not in table.columns]
    if missing:
        raise ValueError(f"a table of calibration estimates needs the columns {', '.join(missing)}")
    table.to_csv(path, index=False, lineterminator="\n")


def read(path: Path, signals=()) -> pd.DataFrame:
    """A table of calibration estimates, every float as written (:func:`write`).

    Parameters
    ----------
    path : Path
    signals : sequence of str
        The signal columns the caller calibrates with; each must be there.

    Returns
    -------
    pandas.DataFrame
        One row per segment and noise level, in the file's order.

    Raises
    ------
    InputError
        Where the file cannot be read as a CSV table, lacks a column, repeats a row's key or holds an estimate or truth
        that is not a finite coverage (a fraction in [0, 1]).
    """
    try:
        table = pd.read_csv(path)
    except (OSError, ValueError, pd.errors.ParserError) as exc:
        raise InputError(f"{path}: not a table of calibration estimates ({exc})") from None
    missing = [c for c in (*COLUMNS, *signals) if c not in table.columns]
    if missing:
        raise InputError(f"{path}: lacks the columns {', '.join(missing)} (made by an older scripts/"
                         "calibrate_intervals.py? make it again with --remake)")
    if table.duplicated(list(KEY)).any():
        raise InputError(f"{path}: {int(table.duplicated(list(KEY)).sum())} rows repeat a (manifest, shard, index, "
                         "noise_mm) already there")
    values = table[["true", "estimate"]].to_numpy(float)
    if not (np.isfinite(values).all() and (values >= 0).all() and (values <= 1).all()):
        raise InputError(f"{path}: every true and estimated coverage must be a fraction in [0, 1]")
    return table


def compare(old: pd.DataFrame, new: pd.DataFrame) -> dict:
    """How a table made again (``new``) differs from another (``old``), row by row on :data:`KEY`.

    Returns
    -------
    dict
        ``rows`` (both), ``only_old``, ``only_new`` (rows in one of them), ``moved`` (estimates moved by more than
        each of :data:`MOVES`, keyed by the move as written, ``"1e-06"`` and ``"0.01"``), ``largest`` (the largest
        move, a fraction) and ``rims`` (rows whose count of cut rims differs, where both tables have it).
    """
    both = old.merge(new, on=list(KEY), how="outer", suffixes=("_old", "_new"), indicator=True)
    matched = both[both["_merge"] == "both"]
    move = (matched["estimate_new"] - matched["estimate_old"]).abs()
    out = {"rows": int(len(matched)), "only_old": int((both["_merge"] == "left_only").sum()),
           "only_new": int((both["_merge"] == "right_only").sum()),
           "moved": {f"{m:g}": int((move > m).sum()) for m in MOVES},
           "largest": float(move.max()) if len(move) else 0.0}
    if "rims_old" in matched and "rims_new" in matched:
        out["rims"] = int((matched["rims_old"] != matched["rims_new"]).sum())
    return out
