"""What crosses the benchmark's boundary to a method outside it: sample ids, input files, prediction files.

A method that is not a Python class in colonbench's environment (a C++ SLAM
post-processor, a network in its own conda environment) sees a suite as
files and answers with files (docs/formats.md):

* **inputs**: one PLY per evaluated cloud (binary little-endian, float64
  ``x, y, z`` in mm, noise already added), named by its :func:`sample_id`,
  and ``index.csv`` listing them (``sample_id, file, noise_mm, points``, and
  on the known-length track ``length_mm``); no truth;
* **predictions**: ``<sample_id>.json`` per input, the JSON of ``colonbench
  estimate``: ``{"coverage": float in [0, 1], "holes": [[x, y, z], ...],
  "centerline": [[x, y, z], ...]}`` in mm, the input's frame (more keys are allowed);
  an ``error`` key instead says that the method failed on it, and a
  ``seconds`` key its own time on it.

:func:`read_prediction` checks a prediction file and says in one line what is
wrong with it; the benchmark records that as the segment's failure.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from colonbench.errors import InputError
from colonbench.estimate import Estimate, interval, level, points_array, reasons

#: Columns of an export's ``index.csv``; the known-length track adds :data:`LENGTH_COLUMN`.
INDEX_COLUMNS = ["sample_id", "file", "noise_mm", "points"]
LENGTH_COLUMN = "length_mm"
INDEX_NAME = "index.csv"
#: The export's own record: suite, hash, counts.
EXPORT_NAME = "suite.json"


def sample_id(shard_name: str, index: int, sigma: float) -> str:
    """The id of one evaluated cloud: ``<split>_<shard stem>_<index>_noise<sigma>``.

    Examples
    --------
    >>> sample_id("test/colon-00003-50mm.h5", 2, 0.5)
    'test_colon-00003-50mm_002_noise0.5'
    """
    stem = Path(shard_name).with_suffix("").as_posix().replace("/", "_")
    return f"{stem}_{int(index):03d}_noise{float(sigma):g}"


def with_sample_ids(rows):
    """Per-segment results rows with their ``sample_id`` column (:func:`sample_id` of ``shard``, ``index`` and
    ``noise_mm``) filled in where it is missing or empty: rows made before the column existed get it too."""
    if "sample_id" in rows.columns and rows["sample_id"].notna().all():
        return rows
    ids = [sample_id(s, i, n) for s, i, n in zip(rows["shard"], rows["index"], rows["noise_mm"])]
    if "sample_id" not in rows.columns:
        return rows.assign(sample_id=ids)
    return rows.assign(sample_id=rows["sample_id"].where(rows["sample_id"].notna(), ids))


def segment_id(sample: str, segment: int) -> str:
    """The id of segment ``segment`` of a whole-colon map of sample ``sample`` (``<sample>_seg<k>``)."""
    return f"{sample}_seg{int(segment):03d}"


def write_input(path, points) -> Path:
    """One input cloud as a binary PLY of float64 x, y, z (mm), written atomically."""
    from colonbench.datagen.generate import write_points_ply

    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp")
    write_points_ply(tmp, points)
    tmp.replace(path)
    return path


def write_index(folder, rows: list[dict], track: str = "points") -> Path:
    """``index.csv`` of an input folder (columns :data:`INDEX_COLUMNS`, and the segment's nominal length on the
    known-length track)."""
    import pandas as pd

    path = Path(folder) / INDEX_NAME
    columns = INDEX_COLUMNS + ([LENGTH_COLUMN] if track == "length" else [])
    pd.DataFrame(rows, columns=columns).to_csv(path, index=False)
    return path


def read_prediction(path, method: str = "predictions") -> Estimate:
    """A prediction file, checked.

    Parameters
    ----------
    path : path
        ``<sample_id>.json``.
    method : str
        The name the estimate is given.

    Raises
    ------
    InputError
        No such file, not a JSON object, an ``error`` (the method's own failure: its words), ``coverage``
        missing, not a number, NaN or outside [0, 1], ``holes`` / ``centerline`` not (n, 3) finite numbers,
        ``coverage_interval`` not ``[low, high]`` fractions, or ``seconds`` not seconds
        (:func:`program_seconds`); the message names the file and the fault.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"no prediction {path.name}")
    try:
        obj = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"{path.name}: not valid JSON ({exc})") from None
    if not isinstance(obj, dict):
        raise InputError(f"{path.name}: a JSON {type(obj).__name__}, expected an object with 'coverage'")
    if obj.get("error") not in (None, "", False):   # the method's own word that it failed on this input
        raise InputError(f"{path.name} says: {one_line(obj['error'])}")
    if "coverage" not in obj:
        raise InputError(f"{path.name}: no 'coverage'")
    c = obj["coverage"]
    if isinstance(c, bool) or not isinstance(c, (int, float)):
        raise InputError(f"{path.name}: coverage {c!r} is not a number")
    c = float(c)
    if math.isnan(c) or not 0.0 <= c <= 1.0:
        raise InputError(f"{path.name}: coverage {c} is not a fraction in [0, 1]")
    return Estimate(c, points_array(obj.get("holes"), "holes", path.name),
                    points_array(obj.get("centerline"), "centerline", path.name), method,
                    seconds=program_seconds(obj.get("seconds"), path.name),
                    coverage_interval=interval(obj.get("coverage_interval"), path.name),
                    review=reasons(obj.get("review"), path.name),
                    interval_level=level(obj.get("coverage_interval_level"), path.name))


def program_seconds(value, who: str) -> dict:
    """A prediction's own ``seconds``: a number (``{"program": value}``), an object of numbers per stage (as
    ``colonbench estimate`` writes), or None / absent (``{}``).

    Raises
    ------
    InputError
        Anything else, or a number that is negative or not finite.
    """
    if value is None:
        return {}
    stages = value if isinstance(value, dict) else {"program": value}
    for v in stages.values():
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
            raise InputError(f"{who}: seconds {value!r} is not a number of seconds >= 0 (or an object of them)")
    return {str(k): float(v) for k, v in stages.items()}


def one_line(text, limit: int = 300) -> str:
    """A message as one line of at most ``limit`` characters (whitespace runs made one space)."""
    line = " ".join(str(text).split())
    return line if len(line) <= limit else line[:limit - 3] + "..."
