"""Typed parameters with ranges: a dataclass field that carries its limits, unit and description, and the draw.

Every configuration of colonbench (the generator's, :mod:`colonbench.datagen.config`; the training
augmentations', :mod:`colonbench.augment`) is a frozen dataclass of such fields. A field whose value is a
``(low, high)`` pair is a *range*: each colon, segment, pose or sample draws its own value from it with
:func:`draw`.
"""

from __future__ import annotations

from dataclasses import field


def param(default, lo, hi, unit: str, doc: str):
    """A config field with its hard limits ``[lo, hi]``, unit and one-line description (in its metadata)."""
    return field(default=default, metadata={"limits": (lo, hi), "unit": unit, "doc": doc})


def draw(rng, value, integer: bool = False):
    """Draw from a ``(low, high)`` range (uniform; whole numbers with ``integer``), or return a scalar as is."""
    if isinstance(value, tuple):
        lo, hi = value
        if integer:
            return int(rng.integers(lo, hi + 1))
        return float(rng.uniform(lo, hi))
    return value
