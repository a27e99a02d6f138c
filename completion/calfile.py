"""A model's calibration file: ``<model stem>.intervals.json`` beside the model, written by
``scripts/calibrate_intervals.py`` (:meth:`colonbench.completion.intervals.Intervals.to_json`) and read back here."""

from __future__ import annotations

import json
from pathlib import Path

from colonbench.completion.intervals import Intervals
from colonbench.errors import InputError

#: Suffix of a model's calibration file.
SUFFIX = ".intervals.json"


def path_for(model: Path) -> Path:
    """The calibration file of a model file: ``<model stem>.intervals.json`` beside it."""
    model = Path(model)
    return model.with_name(model.name.removesuffix(".safetensors") + SUFFIX)


def load(model: Path, steps: str | None) -> Intervals | None:
    """A model's calibration for the steps ``steps`` (``steps=10``, as a method's version names them; None: whatever
    steps), or None where it has none: a user's own model before it is calibrated, or other steps than its own.

    Raises
    ------
    InputError
        Where the file is there but is no calibration colonbench can read: not JSON (cut short, say), fields a
        calibration does not have, or fields that clash.
    """
    path = path_for(model)
    if not path.is_file():
        return None
    try:
        raw = json.loads(path.read_text())
        if not isinstance(raw, dict) or not isinstance(raw.get("source", {}), dict):
            raise ValueError("not a JSON object with an object 'source'")
        cal = Intervals(**raw)
    except (ValueError, TypeError) as exc:          # not JSON (or UTF-8), not a calibration's fields, or they clash
        raise InputError(f"{path} is not a calibration colonbench can read ({exc}): remove it, or make it again "
                         "with scripts/calibrate_intervals.py --model") from None
    return cal if steps is None or cal.source.get("steps") == steps else None
