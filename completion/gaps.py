"""Hole surface put back where the completed tube has no wall: rays across the centerline that meet no surface
(docs/method.md step 6)."""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from colonbench.completion.planes import END_INSET, bases, inside_planes
from colonbench.completion.surface import SURFACE_THRESHOLD


#: Rays cast across the centerline at each station (1 voxel apart) by :func:`wall_gaps`.
GAP_RAYS = 32


#: A ray passes through a gap when it meets no surface voxel, or meets one farther than this many times the
#: station's median wall distance.
GAP_FAR = 3.0


#: Step along a ray, voxels (the shell of surface voxels below the threshold is about 1.5 voxels thick).
GAP_STEP = 0.5


#: A ray is a gap only where the heatmap along it falls below this (a faint wall the network was unsure of):
#: a real colon's surface is open in places (where its walls touch), and a ray through such an opening
#: stays far from every surface, so above it.
GAP_VALLEY = 0.4


#: How far before the wall a ray meets the grown surface voxels, voxels (0.76 for the shell below the
#: threshold, about 0.6 more for the growing).
GAP_GROWN = 1.3


#: A station's own wall distance is its rays' median when at least this share of them meets the wall.
GAP_MIN_HITS = 0.25


def reach_planes(centerline_vox: np.ndarray, planes: list, heatmap: np.ndarray | None = None,
                 lumen: float = GAP_VALLEY) -> np.ndarray:
    """The line run on straight from each end towards that end's plane, where the plane lies beyond the end.

    A plane pushed out to the cloud's extent, or a cut rim found past the
    line's end (:func:`rim_planes`), leaves a stretch of the segment beyond
    the line; the line is extended there in steps of 1 voxel along the
    plane's outward normal, up to the plane, and (given the heatmap) only
    while it stays in the lumen: it stops before the first point where the
    heatmap falls below ``lumen``, a wall's level (:data:`GAP_VALLEY`). A short
    line that lies off the lumen's axis would otherwise run on across the
    colon, and its stations would cast rays from outside the tube.

    Parameters
    ----------
    centerline_vox : (m, 3) float
        Ordered from the first plane's end to the second's, voxels.
    planes : list of (point, inward normal)
        One per end, in the line's order (:func:`segment_planes`); with any other count the line
        comes back as it is.
    heatmap : (S, S, S) float, optional
        The target heatmap the line lies in.
    lumen : float
        The run-on stays where the heatmap is at or above this.

    Returns
    -------
    (m + k, 3) float
        The line with ``k`` points added before its start and after its end, voxels.
    """
    c = np.asarray(centerline_vox, dtype=float)
    if len(c) < 2 or len(planes) != 2:
        return c
    parts = [c]
    for end, (point, inward), first in ((c[0], planes[0], True), (c[-1], planes[1], False)):
        inward = np.asarray(inward, dtype=float)
        beyond = float((end - np.asarray(point, dtype=float)) @ inward)     # how far the end lies inside
        if beyond <= 1.0:
            continue
        ext = end - np.arange(1.0, np.ceil(beyond) + 1.0)[:, None] * inward
        if heatmap is not None:
            wall = np.nonzero(ndimage.map_coordinates(heatmap, ext.T, order=1, mode="nearest") < lumen)[0]
            ext = ext[:wall[0]] if len(wall) else ext
        parts = [ext[::-1]] + parts if first else parts + [ext]
    return np.concatenate(parts)


def _station_frames(centerline_vox: np.ndarray, planes: list, inset: float, heatmap: np.ndarray) -> tuple:
    """Stations 1 voxel apart along the line (run on towards the planes in the lumen, :func:`reach_planes`)
    between the planes, their unit tangents and two normals."""
    c = reach_planes(centerline_vox, planes, heatmap)
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(c, axis=0), axis=1))])
    at = np.arange(0.5, s[-1], 1.0)
    p = np.stack([np.interp(at, s, c[:, k]) for k in range(3)], axis=1)
    t = np.gradient(ndimage.gaussian_filter1d(p, 2.0, axis=0, mode="nearest"), axis=0) if len(p) > 1 else p * 0
    norm = np.linalg.norm(t, axis=1, keepdims=True)
    keep = (norm[:, 0] > 0) & inside_planes(p, planes, inset)
    p, t = p[keep], t[keep] / norm[keep]
    return (p, t, *bases(t))


def wall_gaps(heatmap: np.ndarray, centerline_vox: np.ndarray, planes: list, threshold: float = SURFACE_THRESHOLD,
              rays: int = GAP_RAYS, far: float = GAP_FAR, inset: float = END_INSET,
              valley: float = GAP_VALLEY) -> tuple[np.ndarray, np.ndarray]:
    """Patches of hole surface where the completed tube has no wall.

    From stations 1 voxel apart along the centerline, between the segment's
    planes (the line run on straight, in the lumen, towards a plane that lies
    beyond its end: :func:`reach_planes`), ``rays`` rays perpendicular to the line are marched through the
    heatmap. A ray that meets no voxel below ``threshold`` inside the grid,
    or meets the first one farther than ``far`` times the station's median
    wall distance, passes where the heatmap holds no wall; it is a gap when
    the heatmap along it still falls below ``valley`` (a faint wall the
    network was unsure of, not an opening of the true surface, which a
    collapsed real colon has where its walls touch). Each such ray gets
    a quad of the tube's wall at the station's median distance (the median
    of all stations' where fewer than :data:`GAP_MIN_HITS` of its rays meet
    the wall), 1 voxel long and one ray's angle wide: its area is that of
    the missing cylinder wall, ``r dtheta ds``.

    Parameters
    ----------
    heatmap : (S, S, S) float
    centerline_vox : (m, 3) float
    planes : list of (point, inward normal)
        The planes the segment is clipped at (:func:`segment_planes`).

    Returns
    -------
    vertices : (4 k, 3) float
        Voxel coordinates; four per gap, none shared.
    faces : (2 k, 3) int
    """
    none = (np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64))
    if len(centerline_vox) < 2:
        return none
    p, t, u, v = _station_frames(centerline_vox, planes, inset, heatmap)
    if len(p) == 0:
        return none
    size = heatmap.shape[0]
    theta = np.arange(rays) * 2 * np.pi / rays
    d = np.cos(theta)[None, :, None] * u[:, None] + np.sin(theta)[None, :, None] * v[:, None]   # (m, rays, 3)
    r = np.arange(GAP_STEP, float(size), GAP_STEP)
    # the surface voxels, grown by their 6 neighbours so that no ray slips between two of them diagonally;
    # a ray meets it about a voxel before the wall (GAP_GROWN)
    wall = ndimage.binary_dilation(heatmap < threshold).ravel()
    with np.errstate(divide="ignore", invalid="ignore"):
        exits = np.where(d > 0, (size - 0.5 - p[:, None]) / d, np.where(d < 0, (-0.5 - p[:, None]) / d, np.inf))
    exit_r = exits.min(axis=-1)                                                                  # (m, rays)
    x = np.rint(p[:, None, None] + d[:, :, None] * r[None, None, :, None]).astype(np.int64)       # (m, rays, k, 3)
    np.clip(x, 0, size - 1, out=x)
    flat = (x[..., 0] * size + x[..., 1]) * size + x[..., 2]
    within = r < exit_r[..., None]
    hit = wall[flat] & within
    first = np.where(hit.any(axis=-1), r[hit.argmax(axis=-1)] + GAP_GROWN, np.inf)                 # (m, rays)
    faint = np.where(within, heatmap.ravel()[flat], np.inf).min(axis=-1) < valley                  # (m, rays)
    met = np.isfinite(first)
    if not met.any():
        return none
    enough = met.sum(axis=1) >= GAP_MIN_HITS * rays
    radius = np.full(len(p), float(np.median(first[met])))
    radius[enough] = [np.median(f[np.isfinite(f)]) for f in first[enough]]
    gap = (~met | (first > far * radius[:, None])) & faint
    i, j = np.nonzero(gap)
    if len(i) == 0:
        return none
    half = np.pi / rays
    corners = []
    for da, ds in ((-half, -0.5), (half, -0.5), (half, 0.5), (-half, 0.5)):
        a = theta[j] + da
        corners.append(p[i] + ds * t[i] + radius[i, None] * (np.cos(a)[:, None] * u[i] + np.sin(a)[:, None] * v[i]))
    vertices = np.stack(corners, axis=1).reshape(-1, 3)
    base = 4 * np.arange(len(i))[:, None]
    faces = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]])
    return vertices, faces
