"""A segment in its context: the stretch of centerline it spans, its grid, and the slab input channel.

A segment cut from a whole reconstruction (``colonbench map``) knows two things
a lone segment does not: its cutting planes, and its neighbours' surface. An
in-context model (``colonbench train`` on a context pack, docs/mapping.md) is
given both. Its grid covers the segment's points, its neighbours' up to a
margin, and the centerline of that stretch (so an end that was never observed
still lies inside the grid); its second input channel, the *slab*, is 1 on
the voxels that belong to the segment and 0 on its context:

    slab[v] = 1  if  lo <= s(v) <= hi  else 0

with ``s(v)`` the arc length of the centerline point nearest to voxel ``v``
(the centerline extended straight past both ends, so voxels beyond an end
fall outside), the same rule by which the map clips a completed surface to
its segment (:func:`colonbench.mapping.colonmap.clip_between`) and by which
the whole-colon truth assigns faces to a stretch of colon. Training data
(:mod:`colonbench.mapping.contextpack`) and inference
(:class:`colonbench.completion.method.Predictor`) both call :func:`context_grid`
and :func:`slab_occupancy`, so the two see the same thing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from colonbench.errors import InputError
from colonbench.grid import GRID_MARGIN, GRID_MIN_EXTENT_MM, GRID_SIZE, Grid, axes_around, check_points, fit_grid

#: How far the centerline is extended straight past each end when voxels are assigned to arc lengths, mm.
EXTEND_MM = 200.0
#: The shortest stretch of centerline whose chord gives the grid's first axis, mm.
MIN_CHORD_MM = 5.0


@dataclass(frozen=True)
class Slab:
    """A segment's stretch of centerline, and the context around it.

    Attributes
    ----------
    line : (m, 3) float
        Centerline points, mm, in order, spanning at least the segment (the
        map passes the segment and its context margin).
    arc : (m,) float
        Their arc lengths, mm, increasing.
    lo, hi : float
        The segment's arc-length window, mm.
    """

    line: np.ndarray
    arc: np.ndarray
    lo: float
    hi: float

    def __post_init__(self):
        line, arc = np.asarray(self.line, dtype=float), np.asarray(self.arc, dtype=float)
        if line.ndim != 2 or line.shape[1] != 3 or len(line) < 2 or arc.shape != (len(line),):
            raise InputError(f"a slab needs an (m, 3) centerline of 2 or more points and m arc lengths, got "
                             f"{line.shape} and {arc.shape}")
        if not (np.all(np.isfinite(line)) and np.all(np.isfinite(arc)) and np.all(np.diff(arc) >= 0)):
            raise InputError("a slab's centerline must be finite with non-decreasing arc lengths")
        if not self.hi > self.lo:
            raise InputError(f"a slab's window must have hi > lo, got [{self.lo}, {self.hi}]")
        object.__setattr__(self, "line", line)
        object.__setattr__(self, "arc", arc)

    def key(self) -> bytes:
        """Bytes that identify the slab (a prediction cache key)."""
        return self.line.tobytes() + self.arc.tobytes() + np.array([self.lo, self.hi]).tobytes()


def _end_direction(line: np.ndarray, arc: np.ndarray, first: bool, chord_mm: float = 5.0) -> np.ndarray:
    """Unit direction out of the line's first (or last) end: along the chord from ``chord_mm`` inside."""
    if first:
        d = line[0] - line[min(int(np.searchsorted(arc, arc[0] + chord_mm)), len(line) - 1)]
    else:
        d = line[-1] - line[max(int(np.searchsorted(arc, arc[-1] - chord_mm)) - 1, 0)]
    n = np.linalg.norm(d)
    if n < 1e-9:
        raise InputError("a slab's centerline has no direction at its ends (its points coincide)")
    return d / n


def extended(line: np.ndarray, arc: np.ndarray, extend_mm: float = EXTEND_MM, step_mm: float = 2.0):
    """The centerline continued straight past both ends along its end directions (about 5 mm chords).

    Returns
    -------
    line : (m', 3) float
    arc : (m',) float
        Arc length running on past the ends (below the first, above the last).
    """
    t = np.arange(step_mm, extend_mm + step_mm / 2, step_mm)
    head = line[0] + t[::-1, None] * _end_direction(line, arc, first=True)
    tail = line[-1] + t[:, None] * _end_direction(line, arc, first=False)
    return np.vstack([head, line, tail]), np.concatenate([arc[0] - t[::-1], arc, arc[-1] + t])


def point_at(line: np.ndarray, arc: np.ndarray, at: float) -> np.ndarray:
    """(3,) the point of a polyline at arc length ``at`` (mm; clamped to its ends), linearly interpolated."""
    return np.array([np.interp(at, arc, line[:, k]) for k in range(3)])


def stretch(line: np.ndarray, arc: np.ndarray, lo: float, hi: float, context_mm: float) -> Slab:
    """The :class:`Slab` of the segment ``[lo, hi]`` of a centerline: its points over the segment and
    ``context_mm`` beyond each end, with one more point on each side where there is one."""
    a = max(int(np.searchsorted(arc, lo - context_mm)) - 1, 0)
    b = min(int(np.searchsorted(arc, hi + context_mm, side="right")) + 1, len(arc))
    return Slab(line[a:b], arc[a:b], lo, hi)


def context_rotation(points: np.ndarray, slab: Slab) -> np.ndarray:
    """(3, 3) grid rotation of a segment in context: first row along the chord of its stretch of centerline.

    The chord from the centerline at ``lo`` to the one at ``hi`` is the segment's axis, however short and
    wide the segment is; the other two rows are the points' principal axes across it
    (:func:`colonbench.grid.axes_around`, as :func:`colonbench.grid.tube_axes` does).
    """
    ends = np.stack([np.interp([slab.lo, slab.hi], slab.arc, slab.line[:, k]) for k in range(3)], axis=1)
    axis = ends[1] - ends[0]
    if np.linalg.norm(axis) < MIN_CHORD_MM:  # a tight bend: the whole line's chord
        axis = slab.line[-1] - slab.line[0]
    if np.linalg.norm(axis) < 1e-6:
        raise InputError("a slab's centerline has no direction (its ends coincide)")
    return axes_around(axis, points)


def context_grid(points, slab: Slab, size: int = GRID_SIZE, margin: int = GRID_MARGIN,
                 min_extent_mm: float = GRID_MIN_EXTENT_MM, **_ignored) -> Grid:
    """The grid of a segment in context: its points and its stretch of centerline inside, axes along the chord.

    Parameters
    ----------
    points : (n, 3) float
        The segment's points and its context's, mm.
    slab : Slab
        Its centerline: every point of ``slab.line`` lies inside the grid too.
    size, margin, min_extent_mm
        As :func:`colonbench.grid.fit_grid` (a model's ``grid_options``; others, such as ``axes``, do not apply).
    """
    pts = check_points(points)
    rot = context_rotation(pts, slab)
    return fit_grid(np.vstack([pts, slab.line]), size=size, margin=margin, rotation=rot, min_extent_mm=min_extent_mm)


def slab_occupancy(grid: Grid, slab: Slab) -> np.ndarray:
    """(S, S, S) bool: the voxels whose nearest point of the (extended) centerline lies in ``[lo, hi]``."""
    from scipy.spatial import cKDTree

    line, arc = extended(slab.line, slab.arc)
    r = np.arange(grid.size, dtype=float)
    ijk = np.stack(np.meshgrid(r, r, r, indexing="ij"), axis=-1).reshape(-1, 3)
    _, near = cKDTree(line).query(grid.to_mm(ijk))
    s = arc[near]
    return ((s >= slab.lo) & (s <= slab.hi)).reshape((grid.size,) * 3)
