"""Paths through the lumen of a reconstruction: the wall rasterised, the enclosed voxels found by rays, and the
minimal path through each piece of the enclosed lumen, guided by the camera trajectory where there is one.

Steps 1 to 4 of :mod:`colonbench.mapping.reconstruction_centerline`; :class:`Piece` is what they give."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage

from colonbench import paths
from colonbench.polyline import resample


#: Pieces of the enclosed lumen shorter than this are dropped (specks in folds), mm.
MIN_PIECE_MM = 20.0


#: With a camera trajectory (:func:`_piece_path`): the fall-off of the path's speed away from it, mm ...
GUIDE_SIGMA_MM = 10.0


#: ... the speed factor far from it ...
GUIDE_FLOOR = 0.01


#: ... the path's extremities lie within this of it, mm ...
GUIDE_NEAR_MM = 15.0


#: ... and the trajectory guides the path where the lumen's own path leaves out this much of it, mm.
GUIDE_MISSED_MM = 20.0


#: The ray directions: the 26-neighbourhood.
DIRECTIONS = np.array([(i, j, k) for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1)
                       if (i, j, k) != (0, 0, 0)])


@dataclass
class Piece:
    """One uninterrupted stretch of the colon's centerline.

    Attributes
    ----------
    points : (n, 3) float
        The polyline, mm, 1 mm spacing, ordered along the colon.
    radius : float
        Median distance from the centerline to the wall, mm.
    unseen : list of (float, float)
        Arc-length intervals of the piece (mm from its first point) where it
        runs along the camera trajectory over a stretch with no reconstruction
        (:func:`bridge_by_trajectory`).
    """

    points: np.ndarray
    radius: float
    unseen: list = field(default_factory=list)

    @property
    def length(self) -> float:
        """Arc length, mm."""
        return float(np.linalg.norm(np.diff(self.points, axis=0), axis=1).sum())


def _shift(a: np.ndarray, step) -> np.ndarray:
    """``a`` moved by ``-step`` (voxel ``x`` holds ``a[x + step]``), False outside."""
    out = np.zeros_like(a)
    src, dst = [], []
    for s, n in zip(step, a.shape):
        s = int(s)
        if abs(s) >= n:
            return out
        src.append(slice(max(s, 0), n + min(s, 0)))
        dst.append(slice(max(-s, 0), n + min(-s, 0)))
    out[tuple(dst)] = a[tuple(src)]
    return out


def ray_hits(wall: np.ndarray, max_steps: int | None = None) -> np.ndarray:
    """For each voxel, in how many of the 26 grid directions a ray meets the wall.

    Parameters
    ----------
    wall : (X, Y, Z) bool
    max_steps : int, optional
        Rays end after this many voxel steps (default: the grid's largest side).

    Returns
    -------
    (X, Y, Z) uint8
    """
    wall = np.asarray(wall, bool)
    max_steps = max(wall.shape) if max_steps is None else int(max_steps)
    hits = np.zeros(wall.shape, np.uint8)
    for d in DIRECTIONS:
        seen, k = wall.copy(), 1
        while k < max_steps:
            seen |= _shift(seen, d * k)
            k *= 2
        hits += seen
    return hits


def rasterise(points: np.ndarray, voxel_mm: float, pad: int):
    """Occupancy of ``points`` on a grid of ``voxel_mm``, with ``pad`` empty voxels around.

    Returns
    -------
    occupied : (X, Y, Z) bool
    origin : (3,) float
        Centre of voxel (0, 0, 0), mm.
    """
    lo = points.min(axis=0) - pad * voxel_mm
    idx = np.round((points - lo) / voxel_mm).astype(np.int64)
    shape = idx.max(axis=0) + pad + 1
    occupied = np.zeros(tuple(shape), bool)
    occupied[tuple(idx.T)] = True
    return occupied, lo


def _piece_path(inside: np.ndarray, dist: np.ndarray, voxel_mm: float,
                guide: np.ndarray | None = None) -> np.ndarray:
    """Voxel path between the geodesic extremities of one piece, keeping to its middle.

    ``guide`` ((X, Y, Z) float, mm, optional): each voxel's distance to the camera trajectory. Where the
    trajectory passes through the piece, the extremities are sought among the voxels within
    :data:`GUIDE_NEAR_MM` of it; and where the path leaves out part of the trajectory
    (:func:`misses_trajectory`: a shortcut through a hole between two limbs that touch), it is sought
    again with the speed falling off away from the trajectory (:func:`trajectory_weight`), so that it
    follows the colon the scope went through. A path that misses nothing is kept as it is: the
    trajectory wanders off the lumen's middle, and a path drawn to it everywhere would follow it.
    """
    near = inside
    if guide is not None:  # the largest stretch of the lumen around the trajectory
        near = paths.largest_component(inside & (guide <= GUIDE_NEAR_MM))
        if near.sum() < 8:  # the trajectory hardly enters this piece
            near, guide = inside, None
    a, b = paths.extremities(near, dist, voxel_mm)
    path = paths.middle_path(inside, dist, a, b, voxel_mm)
    if guide is None or not misses_trajectory(path, inside, dist, guide, voxel_mm):
        return path
    return paths.middle_path(inside, dist, a, b, voxel_mm, weight=trajectory_weight(guide))


def piece_paths(inside: np.ndarray, dist: np.ndarray, voxel_mm: float, guide: np.ndarray | None = None,
                 min_mm: float = MIN_PIECE_MM) -> list[np.ndarray]:
    """Voxel paths of one piece (:func:`_piece_path`): one, or one per stretch of the lumen the scope went through.

    With the trajectory, the piece's voxels within :data:`GUIDE_NEAR_MM` of it can fall apart into
    several stretches of at least ``min_mm`` across: two limbs joined only through a hole between them,
    away from where the scope went, with the colon that links them not enclosed (collapsed, or not
    reconstructed). One path would keep to one limb and leave the other out. Each stretch then gets its
    own path, in the piece without the other stretches, and the map joins them along the scope
    (:func:`split_at_shortcuts`, :func:`bridge_by_trajectory`).
    """
    if guide is not None:
        label, n = ndimage.label(inside & (guide <= GUIDE_NEAR_MM))
        if n > 1:
            spans = [np.linalg.norm([(s.stop - s.start) * voxel_mm for s in box])
                     for box in ndimage.find_objects(label)]
            stretches = [k + 1 for k, span in enumerate(spans) if span >= min_mm]
            if len(stretches) > 1:
                return [_piece_path(inside & ((label == k) | (label == 0)), dist, voxel_mm, guide)
                        for k in stretches]
    return [_piece_path(inside, dist, voxel_mm, guide)]


def misses_trajectory(path: np.ndarray, inside: np.ndarray, dist: np.ndarray, guide: np.ndarray,
                      voxel_mm: float, missed_mm: float = GUIDE_MISSED_MM) -> bool:
    """Whether a voxel path leaves out at least ``missed_mm`` of the trajectory through the lumen.

    A trajectory voxel (``guide`` below half a voxel) of the lumen is left out
    when it lies farther from the path than twice the path's median depth
    and than :data:`GUIDE_NEAR_MM`: the path took a shortcut past the colon
    the scope went through.
    """
    from scipy.spatial import cKDTree

    on = np.argwhere(inside & (guide <= 0.5 * voxel_mm))
    if len(on) == 0 or len(path) == 0:
        return False
    d, _ = cKDTree(path).query(on)
    depth = float(np.median(dist[tuple(np.asarray(path).T)]))
    far = d * voxel_mm > max(2.0 * depth, GUIDE_NEAR_MM)
    return bool(far.sum() * voxel_mm >= missed_mm)


def trajectory_weight(distance_mm: np.ndarray, sigma_mm: float = GUIDE_SIGMA_MM,
                      floor: float = GUIDE_FLOOR) -> np.ndarray:
    """Speed factor of a voxel at ``distance_mm`` from the camera trajectory: ``floor + exp(-(d / sigma)^2)``.

    1 on the trajectory, 0.37 a sigma away, about ``floor`` beyond two sigmas: a path
    through a hole between two limbs, a radius or more from where the scope went, costs
    tens of times its length, while the lumen around the trajectory stays open to a path
    that keeps to its middle.
    """
    return floor + np.exp(-(np.asarray(distance_mm, float) / sigma_mm) ** 2)


def trajectory_distance(positions: np.ndarray, origin: np.ndarray, shape: tuple, voxel_mm: float) -> np.ndarray:
    """(X, Y, Z) distance, mm, from each voxel of a grid (``origin`` the centre of voxel 0) to the trajectory.

    The positions are joined in time order and resampled at half a voxel, so
    that sparse poses still draw a continuous path; those outside the grid are
    left out (their voxels' distances are then measured to the rest).
    """
    import edt

    line = resample(np.asarray(positions, float), 0.5 * voxel_mm) if len(positions) > 1 else np.asarray(positions)
    idx = np.round((line - origin) / voxel_mm).astype(np.int64)
    idx = idx[np.all((idx >= 0) & (idx < np.array(shape)), axis=1)]
    free = np.ones(shape, bool)
    if len(idx) == 0:
        return np.full(shape, np.inf)
    free[tuple(idx.T)] = False
    return edt.edt(free, anisotropy=(voxel_mm,) * 3)
