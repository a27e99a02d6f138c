"""The midline of a real colon's lumen: moved to the centres of its cross-sections, its turning held to the lumen's
width, and the stretches where the lumen has collapsed found (:func:`recentre`; :mod:`colonbench.datagen.lumen`
imports the lumen surface)."""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from colonbench.polyline import Centerline, perpendicular_basis


#: Cross-sections are searched this far from the midline, mm.
MAX_RADIUS_MM = 60.0


#: A cross-section of equivalent radius below this is collapsed, mm.
MIN_RADIUS_MM = 5.0


#: Spacing of the cross-sections that re-centre the midline, mm.
SECTION_STEP_MM = 2.0


#: Gaussian smoothing of the midline before and after re-centring, mm.
SMOOTH_MM = 6.0


#: A section's core, whose centroid is the lumen's centre there: its points at least this share as deep
#: (as far from the wall) as the deepest.
CORE_SHARE = 0.8


#: The re-centred line's radius of curvature is at least this share of the lumen's local radius.
MIN_TURN_RATIO = 0.5


#: Length over which the line's turning is measured, mm.
CURVATURE_WINDOW_MM = 3.0


def _smooth_polyline(points: np.ndarray, sigma_mm: float, spacing: float = 1.0) -> Centerline:
    """A polyline resampled at ``spacing`` and smoothed by a Gaussian of ``sigma_mm`` (ends kept in place)."""
    cl = Centerline.from_points(points).resample(spacing)
    pts = cl.points
    if sigma_mm > 0 and len(pts) > 3:
        pad = int(3 * sigma_mm / spacing)
        ext = np.concatenate([2 * pts[:1] - pts[pad:0:-1], pts, 2 * pts[-1:] - pts[-2:-pad - 2:-1]])
        pts = ndimage.gaussian_filter1d(ext, sigma_mm / spacing, axis=0, mode="nearest")[pad:pad + len(pts)]
    return Centerline.from_points(pts)


def cross_sections(cavity: np.ndarray, origin: np.ndarray, voxel: float, centerline: Centerline,
                   step_mm: float = SECTION_STEP_MM, max_radius_mm: float = MAX_RADIUS_MM):
    """Middle and area of the lumen's cross-section perpendicular to a centerline, every ``step_mm``.

    The cross-section at a point is the connected piece of the lumen in the
    plane perpendicular to the centerline that holds the point (or, when the
    point is outside the lumen, the piece nearest to it within a quarter of
    ``max_radius_mm``); other loops of the colon cut by the same plane are
    other pieces.

    Returns
    -------
    s : (k,) float
        Arc lengths of the sections, mm.
    centroid : (k, 3) float
        Middle of the section: the centroid of its points at least 80 % as
        far from its edge as the deepest one. NaN where no section was found.
    area : (k,) float
        mm^2, 0 where none.
    """
    step = 0.5 * voxel
    r = np.arange(-max_radius_mm, max_radius_mm + step / 2, step)
    U, V = np.meshgrid(r, r, indexing="ij")
    s = np.arange(0.0, centerline.length + 1e-9, step_mm)
    points = centerline.point_at(s)
    u, v = perpendicular_basis(centerline.tangent_at(s))
    centroid = np.full((len(s), 3), np.nan)
    area = np.zeros(len(s))
    mid = len(r) // 2
    reach = (0.25 * max_radius_mm / step) ** 2
    limit = np.array(cavity.shape) - 1
    for i in range(len(s)):
        plane = points[i] + U[..., None] * u[i] + V[..., None] * v[i]
        idx = np.rint((plane - origin) / voxel).astype(int)
        ok = np.all((idx >= 0) & (idx <= limit), axis=-1)
        idx = np.clip(idx, 0, limit)
        inside = cavity[idx[..., 0], idx[..., 1], idx[..., 2]] & ok
        if not inside.any():
            continue
        lab, _ = ndimage.label(inside)
        if lab[mid, mid]:
            pick = lab[mid, mid]
        else:
            cand = np.argwhere(lab > 0)
            d2 = ((cand - mid) ** 2).sum(axis=1)
            if d2.min() > reach:
                continue
            pick = lab[tuple(cand[np.argmin(d2)])]
        sel = lab == pick
        # the middle of the section's widest part: the centroid of its points at least CORE_SHARE as deep as
        # the deepest (a flattened or kidney-shaped section has its plain centroid near, or in, a wall)
        depth = ndimage.distance_transform_edt(sel)
        core = depth >= CORE_SHARE * depth.max()
        centroid[i] = plane[core].mean(axis=0)
        area[i] = sel.sum() * step * step
    return s, centroid, area


def smooth_along(values: np.ndarray, step_mm: float, median_mm: float, smooth_mm: float) -> np.ndarray:
    """Values sampled along a line, median-filtered over ``median_mm`` then Gaussian-smoothed (sigma ``smooth_mm``).

    The median lets one odd section (a fold, a pocket, an oblique cut) move one
    sample, not the line; the Gaussian makes the line smooth.

    Parameters
    ----------
    values : (m, d) float
        One row per sample, ``step_mm`` apart along the line.
    step_mm, median_mm, smooth_mm : float
        mm; the median window is an odd number of samples, at least 3.
    """
    width = max(3, int(round(median_mm / step_mm)) | 1)
    out = ndimage.median_filter(values, size=(width, 1), mode="nearest")
    return ndimage.gaussian_filter1d(out, smooth_mm / step_mm, axis=0, mode="nearest")


def outline_core_centre(outline: np.ndarray, pixel_mm: float = 0.5) -> np.ndarray:
    """The centre of a closed cross-section outline: the centroid of its core, mm; (2,).

    The core is the part of the section at least :data:`CORE_SHARE` as far from
    the outline as its deepest point, as in :func:`cross_sections`, on a raster
    of ``pixel_mm``.

    Parameters
    ----------
    outline : (n, 2) float
        The section's closed outline in its plane, mm (any start, either orientation).
    pixel_mm : float
        Raster pixel, mm.
    """
    from skimage.draw import polygon

    outline = np.asarray(outline, dtype=float)
    lo = outline.min(axis=0) - 2.0 * pixel_mm
    shape = np.ceil((outline.max(axis=0) - lo) / pixel_mm).astype(int) + 3
    inside = np.zeros(shape, bool)
    rr, cc = polygon(*((outline - lo) / pixel_mm).T, shape=shape)
    inside[rr, cc] = True
    depth = ndimage.distance_transform_edt(inside)
    return np.argwhere(depth >= CORE_SHARE * depth.max()).mean(axis=0) * pixel_mm + lo


def recentre(cavity: np.ndarray, origin: np.ndarray, voxel: float, midline, iterations: int = 3,
             min_radius_mm: float = MIN_RADIUS_MM, smooth_mm: float = SMOOTH_MM,
             max_radius_mm: float = MAX_RADIUS_MM) -> tuple[Centerline, np.ndarray, list]:
    """A centerline through the middle of the lumen, from a rough midline.

    The midline is smoothed, then moved ``iterations`` times towards the
    centroids of its cross-sections (:func:`cross_sections`): by the
    displacement to them, median-filtered and smoothed along the line and at
    most half the section's radius, so that an oblique section at a bend or a
    deep pocket cannot throw the line off its course. Where a
    section is missing or narrower than ``min_radius_mm`` (equivalent radius
    sqrt(area / pi)), the lumen is collapsed: the line keeps its previous
    course there, and the stretch is reported.

    Returns
    -------
    centerline : Centerline
        0.5 mm spacing.
    radius : (n,) float
        Equivalent radius at each of its points, mm (0 where collapsed).
    collapsed : list of (float, float)
        Arc-length intervals of collapsed stretches, mm.
    """
    line = _smooth_polyline(np.asarray(midline, float), smooth_mm)
    for _ in range(iterations):
        s, cen, area = cross_sections(cavity, origin, voxel, line, max_radius_mm=max_radius_mm)
        radius = np.sqrt(area / np.pi)
        good = np.isfinite(cen[:, 0]) & (radius >= min_radius_mm)
        pts, tangent = line.point_at(s), line.tangent_at(s)
        # move by a smoothed displacement (median then Gaussian along the line, at most half the radius):
        # moving each point to its own centroid lets an oblique or pocketed section make the line zig-zag
        move = np.where(good[:, None], np.nan_to_num(cen - pts), 0.0)
        move = smooth_along(move, SECTION_STEP_MM, 2 * smooth_mm, smooth_mm)
        # only across the line: a move along it (the filters mix in the neighbours' moves at a bend) lets
        # points overtake each other, and the line folds back on itself in a cusp
        move -= (move * tangent).sum(axis=1, keepdims=True) * tangent
        norm = np.linalg.norm(move, axis=1)
        move *= np.minimum(1.0, 0.5 * np.maximum(radius, min_radius_mm) / np.maximum(norm, 1e-12))[:, None]
        line = _smooth_polyline(_unfold(pts + move, tangent), smooth_mm)
    # twice: the sections of the smoothed line can be wider than those the limit was set by
    for _ in range(2):
        line = limit_curvature(line, lambda q, s=s, r=np.maximum(radius, min_radius_mm): np.interp(q, s, r))
        line = line.resample(0.5)
        s, _, area = cross_sections(cavity, origin, voxel, line, max_radius_mm=max_radius_mm)
        radius = np.sqrt(area / np.pi)
    collapsed = collapsed_intervals(s, radius < min_radius_mm)
    along = np.interp(line.arclength, s, radius)
    return line, np.where(along >= min_radius_mm, along, 0.0), collapsed


def turning_radius(line: Centerline, window_mm: float = CURVATURE_WINDOW_MM) -> np.ndarray:
    """(n,) radius of curvature at each point of ``line``, mm: the window's length over the angle it turns.

    Measured over ``window_mm`` (centred on the point, shortened at the ends) rather than from second
    differences, which a 1 mm polyline makes noisy.
    """
    s = line.arclength
    a = line.tangent_at(np.clip(s - window_mm / 2, 0, s[-1]))
    b = line.tangent_at(np.clip(s + window_mm / 2, 0, s[-1]))
    span = np.minimum(s + window_mm / 2, s[-1]) - np.maximum(s - window_mm / 2, 0.0)
    angle = np.arccos(np.clip((a * b).sum(axis=1), -1.0, 1.0))
    return np.where(angle > 1e-9, span / np.maximum(angle, 1e-9), np.inf)


def limit_curvature(line: Centerline, radius, ratio: float = MIN_TURN_RATIO, sigma_mm: float = 3.0,
                    max_rounds: int = 200) -> Centerline:
    """Smooth ``line`` where it turns more sharply than the lumen around it allows.

    The centerline of a tube cannot bend with a radius of curvature below
    the tube's own radius without its cross-sections overlapping inside the
    lumen; a bend sharper than ``ratio`` times the local lumen radius is a
    kink of the re-centring (a section's middle jumping between two lobes
    of a flattened section, or into a pocket). Such stretches are smoothed
    again, a little at a time (a Gaussian of ``sigma_mm``, blended in where
    the line is too sharp), until none is left or ``max_rounds`` have run;
    the rest of the line is not moved.

    Parameters
    ----------
    line : Centerline
    radius : callable
        ``radius(s)``: the lumen's equivalent radius (mm) at arc lengths ``s`` of ``line`` (mm).
    ratio : float
        Smallest radius of curvature, as a share of the local lumen radius.
    """
    line = line.resample(1.0)
    for _ in range(max_rounds):
        too_sharp = turning_radius(line) < ratio * radius(line.arclength)
        if not too_sharp.any():
            break
        pts = line.points
        weight = np.clip(ndimage.gaussian_filter1d(too_sharp.astype(float), sigma_mm, mode="constant") * 3.0, 0, 1)
        weight[[0, -1]] = 0.0
        smooth = ndimage.gaussian_filter1d(pts, sigma_mm, axis=0, mode="nearest")
        line = Centerline.from_points(pts + weight[:, None] * (smooth - pts)).resample(1.0)
    return line


def _unfold(points: np.ndarray, tangent: np.ndarray) -> np.ndarray:
    """The moved points without those that step back along the line they were moved from.

    ``points`` are the moved section points in order, ``tangent`` the unit tangents of the old line at
    them; a point that does not lie ahead of the last one kept, along its own old tangent, is dropped
    (ends kept), so that the new line cannot fold back.
    """
    keep = [0]
    for i in range(1, len(points) - 1):
        if (points[i] - points[keep[-1]]) @ tangent[i] > 0.0:
            keep.append(i)
    if len(points) > 1:
        if len(keep) > 1 and (points[-1] - points[keep[-1]]) @ tangent[-1] <= 0.0:
            keep.pop()
        keep.append(len(points) - 1)
    return points[keep]


def collapsed_intervals(s: np.ndarray, flag: np.ndarray, pad: float = SECTION_STEP_MM) -> list:
    """Arc-length intervals ``(a, b)`` where ``flag`` holds along ``s``, widened by ``pad``."""
    if not flag.any():
        return []
    edges = np.flatnonzero(np.diff(np.concatenate([[0], flag.astype(int), [0]])))
    return [(float(max(s[a] - pad, 0.0)), float(min(s[b - 1] + pad, s[-1]))) for a, b in zip(edges[::2], edges[1::2])]
