"""A model's calibration file: ``<model stem>.intervals.json`` beside the model, written by
``scripts/calibrate_intervals.py`` (:meth:`colonbench.completion.intervals.Intervals.to_json`) and read back here."""

from __future__ import annotations

import dataclasses
import json
import numbers
from pathlib import Path

from colonbench.completion.intervals import Intervals
from colonbench.completion.modelfile import beside
from colonbench.errors import InputError

#: Suffix of a model's calibration file.
SUFFIX = ".intervals.json"
#: The calibration's fields by the JSON type they must have (the rest of :class:`Intervals`' fields are objects).
_STRINGS = ("scheme", "review_by", "review_by_known")
_NUMBERS = ("level", "review_width", "review_known")
#: Significant digits of every number the calibration file stores (:func:`rounded`).
SIGNIFICANT = 9


def path_for(model: Path) -> Path:
    """The calibration file of a model file: ``<model stem>.intervals.json`` beside it."""
    return beside(model, SUFFIX)


def rounded(value, digits: int = SIGNIFICANT):
    """``value`` (a calibration's JSON: dicts, lists, numbers, strings) with every float rounded to ``digits``
    significant digits, so that the file and its id almost never change with the last bits another machine's kernels
    give the fits (decision record 0168: 1e-15 to 1e-12 of each weight under another BLAS; a number within that of a
    rounding boundary would still flip)."""
    if isinstance(value, dict):
        return {k: rounded(v, digits) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [rounded(v, digits) for v in value]
    return float(f"{value:.{digits}g}") if isinstance(value, float) else value


def fields_problem(raw) -> str:
    """What is wrong with a calibration file's JSON ``raw`` at the level of its fields, or "" where nothing is: not
    an object, fields :class:`Intervals` does not have or lacks, or a field of the wrong JSON type."""
    if not isinstance(raw, dict):
        return f"it holds a JSON {type(raw).__name__}, not an object"
    fields = dataclasses.fields(Intervals)
    unknown = sorted(set(raw) - {f.name for f in fields})
    missing = [f.name for f in fields if f.name not in raw and f.default is dataclasses.MISSING
               and f.default_factory is dataclasses.MISSING]
    if unknown or missing:
        return "; ".join(f"{what} fields: {', '.join(names)}" for what, names in (("unknown", unknown),
                                                                                  ("missing", missing)) if names)
    for name, value in raw.items():
        kind, what = (str, "a string") if name in _STRINGS else (numbers.Real, "a number") if name in _NUMBERS \
            else (dict, "an object")
        if not isinstance(value, kind) or isinstance(value, bool):
            return f"its {name!r} is not {what}"
    return ""


def load(model: Path, steps: str | None) -> Intervals | None:
    """A model's calibration for the steps ``steps`` (``steps=10``, as a method's version names them; None: whatever
    steps), or None where it has none: a user's own model before it is calibrated, or other steps than its own.

    Raises
    ------
    InputError
        Where the file is there but is no calibration colonbench can read: not readable, not JSON (cut short, say),
        fields a calibration does not have, lacks or has of another type, or fields that clash.
    """
    path = path_for(model)
    if not path.is_file():
        return None
    try:
        raw = json.loads(path.read_text())
        problem = fields_problem(raw)
        cal = None if problem else Intervals(**raw)
    except (OSError, ValueError, TypeError, RecursionError) as exc:     # unreadable, not JSON, or fields that clash
        problem = str(exc)
    if problem:
        raise InputError(f"{path} is not a calibration colonbench can read ({problem}): make it again with `python "
                         f"scripts/calibrate_intervals.py --model {model}` (the shipped model's comes with colonbench: "
                         "reinstall it)")
    return cal if steps is None or cal.source.get("steps") == steps else None
