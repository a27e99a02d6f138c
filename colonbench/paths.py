"""Minimal paths through voxel grids (fast marching), shared by centerline extraction everywhere.

The classic recipe (Deschamps & Cohen 2001, used by the paper): compute the
travel time from a start voxel with a speed map that is high in the middle of
the lumen (scikit-fmm), then walk back from the end voxel down the travel time
to the start. The walk is discrete (26-neighbourhood, always descending) and is
then smoothed, which gives a sub-voxel, smooth path.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter1d


def travel_time(speed: np.ndarray, start, mask: np.ndarray | None = None, dx: float = 1.0) -> np.ndarray:
    """Fast-marching travel time from ``start``.

    Parameters
    ----------
    speed : (X, Y, Z) float
        Positive speed where travel is allowed.
    start : (3,) int
        Start voxel.
    mask : (X, Y, Z) bool, optional
        Voxels that may be crossed (default: ``speed > 0``).
    dx : float
        Voxel size (any unit; travel time is in that unit over speed).

    Returns
    -------
    (X, Y, Z) float
        Travel time; ``inf`` where unreachable.
    """
    import skfmm

    mask = speed > 0 if mask is None else mask
    phi = np.ones(speed.shape)
    phi[tuple(start)] = -1.0
    phi = np.ma.MaskedArray(phi, ~mask)
    spd = np.where(mask, np.maximum(speed, 1e-6), 1.0)
    t = skfmm.travel_time(phi, spd, dx=dx)
    out = np.asarray(np.ma.filled(t, np.inf), dtype=np.float64)
    out[tuple(start)] = 0.0
    out[~np.isfinite(out)] = np.inf
    return out


_OFFSETS = np.array([(i, j, k) for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1)
                     if (i, j, k) != (0, 0, 0)])
_STEP = np.linalg.norm(_OFFSETS, axis=1)


def backtrack(time: np.ndarray, end, max_steps: int | None = None) -> np.ndarray:
    """Walk from ``end`` down ``time`` to its zero (the start); voxel path, (n, 3) int, start first.

    Each step goes to the 26-neighbour with the steepest descent of travel time
    per unit length.
    """
    shape = np.array(time.shape)
    cur = np.array(end, dtype=np.int64)
    path = [cur.copy()]
    limit = max_steps or int(time.size)
    for _ in range(limit):
        if time[tuple(cur)] == 0.0:
            break
        nb = cur + _OFFSETS
        ok = np.all((nb >= 0) & (nb < shape), axis=1)
        vals = np.full(len(nb), np.inf)
        vals[ok] = time[nb[ok, 0], nb[ok, 1], nb[ok, 2]]
        slope = (vals - time[tuple(cur)]) / _STEP
        k = int(np.argmin(slope))
        if not np.isfinite(vals[k]) or vals[k] >= time[tuple(cur)]:
            break
        cur = nb[k]
        path.append(cur.copy())
    return np.array(path[::-1])


def smooth_path(path: np.ndarray, sigma: float = 2.0) -> np.ndarray:
    """Gaussian smoothing of a polyline (end points kept); (n, 3) float."""
    p = np.asarray(path, dtype=np.float64)
    if len(p) < 5 or sigma <= 0:
        return p
    out = gaussian_filter1d(p, sigma, axis=0, mode="nearest")
    out[0], out[-1] = p[0], p[-1]
    return out


def farthest_voxel(mask: np.ndarray, start, dx: float = 1.0):
    """The voxel of ``mask`` farthest from ``start`` in geodesic distance inside the mask.

    Returns
    -------
    voxel : (3,) int
    time : (X, Y, Z) float
        Geodesic distance from ``start``.
    """
    t = travel_time(mask.astype(float), start, mask=mask, dx=dx)
    finite = np.where(np.isfinite(t), t, -1.0)
    return np.array(np.unravel_index(int(np.argmax(finite)), t.shape)), t


def largest_component(mask: np.ndarray) -> np.ndarray:
    """The largest face-connected piece of a boolean voxel mask (all False where the mask is empty)."""
    from scipy import ndimage

    label, n = ndimage.label(mask)
    if n == 0:
        return np.zeros_like(mask, dtype=bool)
    return label == 1 + int(np.argmax(np.bincount(label.ravel())[1:]))


def extremities(mask: np.ndarray, depth: np.ndarray, dx: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """The two ends of a tube's longest geodesic path: from its deepest voxel, the farthest voxel ``a``,
    then the voxel ``b`` farthest from ``a`` (both (3,) int).

    ``depth``: each voxel's distance to the wall, same shape as ``mask``.
    """
    seed = np.array(np.unravel_index(int(np.argmax(np.where(mask, depth, -1))), depth.shape))
    a, _ = farthest_voxel(mask, seed, dx=dx)
    b, _ = farthest_voxel(mask, a, dx=dx)
    return a, b


def middle_path(mask: np.ndarray, depth: np.ndarray, a, b, dx: float = 1.0,
                weight: np.ndarray | None = None) -> np.ndarray:
    """(m, 3) int voxel path from ``a`` to ``b`` inside ``mask`` that keeps to the tube's middle.

    Fast marching with the speed ``(depth / max depth)^2`` (times ``weight``,
    a per-voxel factor, where given): the minimal path stays where the wall
    is farthest.
    """
    speed = (depth / max(float(depth[mask].max()), 1e-9)) ** 2
    if weight is not None:
        speed = speed * weight
    return backtrack(travel_time(speed, a, mask=mask, dx=dx), b)

