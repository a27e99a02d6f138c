"""What a coverage-estimation method is (:class:`Method`) and returns (:class:`Estimate`): the contract shared by
methods, ``colonbench estimate`` and the benchmark."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

from colonbench.errors import InputError


def review_count(interval, review) -> float:
    """How many reasons to review an answer gives (``review``, a list), where it says how sure it is (an
    ``interval``, or a reason); NaN for one that says nothing of it: the benchmark's ``review`` column."""
    return float(len(review)) if interval is not None or review else float("nan")


@dataclass
class Estimate:
    """What a coverage-estimation method returns for one partial segment (mm, the input's frame).

    Attributes
    ----------
    coverage : float
        Estimated observed fraction of the segment surface, in [0, 1].
    holes : (k, 3) float
        Points of the estimated holes, mm.
    centerline : (m, 3) float
        Estimated centerline, mm, spacing 0.5 mm.
    method : str
    mesh_vertices : (v, 3) float
        Completed mesh, mm (empty for methods without one).
    mesh_faces : (f, 3) int
    hole_vertices : (v,) bool
        Which mesh vertices are holes.
    seconds : dict
        Wall time per stage.
    coverage_interval : (float, float) or None
        Where the true coverage lies with probability :attr:`interval_level` (fractions), for methods that
        say how sure they are; None for the others.
    interval_level : float
        The interval's nominal coverage (0.9 unless the method documents another).
    review : list of str
        Why the estimate should not be trusted as it is (an interval wider than the method's threshold, a
        fallback taken); empty when there is no reason.
    signals : dict
        What the method's own steps said of the segment (e.g. ``rims``: cut rims found at its ends).
    """

    coverage: float
    holes: np.ndarray
    centerline: np.ndarray
    method: str
    mesh_vertices: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    mesh_faces: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), dtype=np.int64))
    hole_vertices: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    seconds: dict = field(default_factory=dict)
    coverage_interval: tuple | None = None
    interval_level: float = 0.9
    review: list = field(default_factory=list)
    signals: dict = field(default_factory=dict)

    @property
    def review_count(self) -> float:
        """How many reasons to review the estimate gives (:func:`review_count`)."""
        return review_count(self.coverage_interval, self.review)

    def to_json(self) -> dict:
        """The ``estimate`` command's JSON: coverage (with its interval where the method gives one, and why to review
        it), holes, centerline (mm), method."""
        out = {"coverage": float(self.coverage)}
        if self.coverage_interval is not None:
            out.update(coverage_interval=[round(float(x), 6) for x in self.coverage_interval],
                       coverage_interval_level=float(self.interval_level))
        if self.coverage_interval is not None or self.review:
            out["review"] = list(self.review)
        out.update(holes=np.round(self.holes, 4).tolist(), centerline=np.round(self.centerline, 4).tolist(),
                   method=self.method, seconds={k: round(v, 4) for k, v in self.seconds.items()})
        if self.signals:
            out["signals"] = self.signals
        return out


@runtime_checkable
class Method(Protocol):
    """What the benchmark, ``colonbench estimate`` and ``colonbench map`` call: a coverage-estimation method.

    Any object with these attributes is one; nothing needs to be subclassed.

    Attributes
    ----------
    name : str
        Its row in the tables.
    version : str
        Recorded with every result; a run refuses to mix two versions of one method.

    Methods
    -------
    estimate(points)
        ``points``: (n, 3) float, one partial segment, mm, in its own frame. Returns an :class:`Estimate`, or
        a dict with at least ``coverage`` (fraction in [0, 1]) and optionally ``holes`` and ``centerline``
        ((k, 3) mm), the ``colonbench estimate`` JSON contract.
    """

    name: str
    version: str

    def estimate(self, points: np.ndarray) -> "Estimate | dict": ...


def points_array(value, what: str, who: str) -> np.ndarray:
    """``value`` as (n, 3) finite float mm, or an :class:`InputError` naming ``who`` gave what.

    Parameters
    ----------
    value : array_like or None
        None and empty give (0, 3).
    what : str
        ``holes`` or ``centerline``.
    who : str
        The method or file the points came from, as messages name it.
    """
    try:
        a = np.asarray(value if value is not None else np.zeros((0, 3)), dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{who}: {what!r} are not [x, y, z] numbers") from None
    if a.size == 0:
        return np.zeros((0, 3))
    if a.ndim != 2 or a.shape[1] != 3:
        raise InputError(f"{who}: {what!r} has shape {a.shape}; expected (n, 3) points, mm")
    if not np.isfinite(a).all():
        raise InputError(f"{who}: {what!r} holds NaN or infinite values")
    return a


def as_estimate(result, name: str) -> Estimate:
    """A method's return value checked and turned into an :class:`Estimate` (or an :class:`InputError`).

    Parameters
    ----------
    result : Estimate or dict
        What ``estimate(points)`` returned: a dict needs ``coverage``; ``holes`` and ``centerline`` are optional.
    name : str
        The method's name, given to the estimate and named in messages.
    """
    who = f"method {name!r}"
    if isinstance(result, Estimate):
        est = result
    elif isinstance(result, dict):
        if "coverage" not in result:
            raise InputError(f"{who} returned a dict without 'coverage'")
        est = Estimate(result["coverage"], result.get("holes"), result.get("centerline"), name,
                       coverage_interval=result.get("coverage_interval"),
                       interval_level=result.get("coverage_interval_level") or 0.9,
                       review=reasons(result.get("review"), who))
    else:
        raise InputError(f"{who} returned {type(result).__name__}; expected an Estimate or a dict")
    try:
        coverage = float(est.coverage)
    except (TypeError, ValueError):
        raise InputError(f"{who} returned coverage {est.coverage!r}, not a number") from None
    if not (np.isnan(coverage) or -1e-9 <= coverage <= 1 + 1e-9):
        raise InputError(f"{who} returned coverage {coverage}; a fraction in [0, 1] is expected")
    est.coverage = coverage
    est.coverage_interval = interval(est.coverage_interval, who)
    est.interval_level = level(est.interval_level, who)
    est.holes = points_array(est.holes, "holes", who)
    est.centerline = points_array(est.centerline, "centerline", who)
    est.method = name
    return est


def reasons(value, who: str) -> list:
    """A method's ``review`` checked: a list of reasons (strings) to look at the estimate again; [] for None."""
    if value is None:
        return []
    if not isinstance(value, (list, tuple)) or not all(isinstance(r, str) for r in value):
        raise InputError(f"{who} returned review {value!r}; a list of reasons (strings) is expected")
    return list(value)


def interval(value, who: str) -> tuple | None:
    """A method's ``coverage_interval`` checked: None, or ``(low, high)`` fractions with 0 <= low <= high <= 1."""
    if value is None:
        return None
    try:
        low, high = (float(x) for x in value)
    except (TypeError, ValueError):
        raise InputError(f"{who} returned coverage_interval {value!r}; [low, high] fractions are expected") from None
    if not (-1e-9 <= low <= high <= 1 + 1e-9):
        raise InputError(f"{who} returned coverage_interval [{low}, {high}]; fractions with 0 <= low <= high <= 1 "
                         "are expected")
    return (min(max(low, 0.0), 1.0), min(max(high, 0.0), 1.0))


def level(value, who: str) -> float:
    """A method's ``coverage_interval_level`` checked: a number strictly between 0 and 1 (0.9 when None)."""
    if value is None:
        return 0.9
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{who} returned coverage_interval_level {value!r}; a number in (0, 1) is expected") from None
    if not 0.0 < out < 1.0:
        raise InputError(f"{who} returned coverage_interval_level {out}; a number in (0, 1) is expected")
    return out
