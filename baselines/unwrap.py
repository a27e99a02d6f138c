"""2D unwrapping (Ma et al. 2019, the paper's baseline 3): coverage by rasterizing the surface in (arc length, angle).

Each partial point is mapped to cylindrical coordinates around a centerline:
``s``, the arc length of its nearest centerline point, and ``theta``, its
angle in that point's rotation-minimising frame. ``theta`` is scaled by the
mean radius (distance of the points to the centerline), so both axes are in
mm, and the points are rasterized at ``cell_mm`` (about 1 mm). A
morphological closing (fills sampling gaps) then opening (removes isolated
specks), periodic in the angle, gives the observed cells; every empty cell of
the segment's (s, theta) rectangle is a hole cell, and

    coverage = 1 - hole cells / (hole cells + surface cells).

Hole points are the centres of hole cells placed back in 3D at the median
radius of the points in their row. The centerline can be the learned one (as
the paper ran the baseline), the ground truth, or a straight axis through the
points' first principal component (as Ma et al. did, which fails on curved
segments).
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from colonbench.estimate import Estimate
from colonbench.grid import principal_axes
from colonbench.polyline import Centerline

#: Raster cell, mm.
CELL_MM = 1.0
#: Closing and opening radius, cells.
MORPH_CELLS = 1
#: The raster's settings in the methods' versions (``rows=sample``: rows from the nearest line sample's index,
#: since colonbench 1.1; before, from its arc length in floats, which put points on either side of a row's edge
#: under another machine's float noise. ``holes=sample``: a hole cell's line sample from its row in integers, since
#: colonbench 1.2; before, by comparing floats that are equal in exact arithmetic, which another CPU's BLAS kernel
#: decided the other way for whole rows of hole points).
RASTER = f"cell={CELL_MM:g}mm,rows=sample,holes=sample"


def pca_axis(points: np.ndarray, spacing: float = 0.5) -> np.ndarray:
    """A straight centerline: the points' first principal axis, over the extent of their projections."""
    pts = np.asarray(points, dtype=float)
    c = pts.mean(axis=0)
    axis = principal_axes(pts)[0]
    t = (pts - c) @ axis
    n = max(int(np.ceil((t.max() - t.min()) / spacing)), 1)
    return c + np.linspace(t.min(), t.max(), n + 1)[:, None] * axis


def unwrap(points: np.ndarray, centerline: np.ndarray, index: bool = False):
    """Cylindrical coordinates of points around a centerline.

    Returns
    -------
    s : (n,) float
        Arc length of the nearest centerline sample, mm.
    theta : (n,) float
        Angle in that sample's rotation-minimising frame, radians in [0, 2 pi).
    radius : (n,) float
        Distance to that sample, mm.
    line : Centerline
        The centerline (resampled every 0.5 mm).
    frames : tuple of (m, 3) arrays
        Tangent, normal, binormal per centerline sample.
    sample : (n,) int
        With ``index``: the index of each point's nearest centerline sample.
    """
    line = Centerline.from_points(centerline).resample(0.5)
    t, nrm, bin_ = line.frames()
    from scipy.spatial import cKDTree

    _, idx = cKDTree(line.points).query(points)
    rel = points - line.points[idx]
    x, y = np.einsum("ij,ij->i", rel, nrm[idx]), np.einsum("ij,ij->i", rel, bin_[idx])
    out = line.arclength[idx], np.mod(np.arctan2(y, x), 2 * np.pi), np.hypot(x, y), line, (t, nrm, bin_)
    return (*out, idx) if index else out


def row_centre_sample(rows: np.ndarray, n_rows: int, intervals: int) -> np.ndarray:
    """The first sample of an evenly resampled line at or past the centre of each raster row, in integers.

    Sample ``j`` lies at arc length ``j * length / intervals`` and row ``r``'s centre at ``(r + 0.5) / n_rows *
    length``, so the sample is ``ceil((2 r + 1) intervals / (2 n_rows))``. Where ``(2 r + 1) intervals`` is a
    multiple of ``2 n_rows`` (for every row when ``intervals == 2 n_rows``: half of all lengths at a 0.5 mm line
    and 1 mm cells) the centre is a sample exactly, and comparing the two in floats went either way with the last
    bit of the line's length, which another CPU's BLAS kernel moves.

    Parameters
    ----------
    rows : (k,) int
        Raster rows, in ``[0, n_rows)``.
    n_rows : int
        Rows of the raster along the segment.
    intervals : int
        Intervals of the resampled line (its samples less one).

    Returns
    -------
    (k,) int
        Sample indices, in ``[0, intervals]``.
    """
    rows = np.asarray(rows, dtype=np.int64)
    return np.minimum(-(-(2 * rows + 1) * intervals // (2 * n_rows)), intervals)


def _disk(radius: int) -> np.ndarray:
    r = np.arange(-radius, radius + 1)
    return (r[:, None] ** 2 + r[None, :] ** 2) <= radius ** 2


def unwrap_coverage(points, centerline, method: str = "unwrap", cell_mm: float = CELL_MM,
                    morph_cells: int = MORPH_CELLS) -> Estimate:
    """Coverage, hole points and centerline of a partial segment by 2D unwrapping (mm in, mm out).

    Parameters
    ----------
    points : (n, 3) float
        Partial point cloud, mm.
    centerline : (m, 3) float
        The centerline to unwrap around, mm, ordered.
    method : str
        Name recorded in the result.
    """
    pts = np.asarray(points, dtype=float)
    cl = np.asarray(centerline, dtype=float)
    if len(cl) < 2 or len(pts) == 0:
        return Estimate(float("nan"), np.zeros((0, 3)), cl.reshape(-1, 3), method)
    s, theta, radius, line, (_, nrm, bin_), sample = unwrap(pts, cl, index=True)
    r_mean = float(np.mean(radius))
    n_rows = max(int(np.ceil(line.length / cell_mm)), 1)
    n_cols = max(int(np.round(2 * np.pi * r_mean / cell_mm)), 4)
    # rows from the nearest sample's index in integers: the resampled line's samples are evenly spaced, so
    # s / length * n_rows is k * n_rows / (samples - 1), which for many k is an integer in exact arithmetic and
    # lands a last bit either side of a row's edge in floats (another CPU moved whole rows of points)
    row = np.minimum(sample * n_rows // max(len(line.points) - 1, 1), n_rows - 1)
    col = np.clip((theta / (2 * np.pi) * n_cols).astype(int), 0, n_cols - 1)
    occupied = np.zeros((n_rows, n_cols), bool)
    occupied[row, col] = True
    if morph_cells > 0:
        disk = _disk(morph_cells)
        pad = morph_cells
        # periodic in the angle; at the segment's two ends the edge rows are repeated, so neither
        # operation eats into them
        wrapped = np.pad(occupied, ((0, 0), (2 * pad, 2 * pad)), mode="wrap")
        wrapped = np.pad(wrapped, ((2 * pad, 2 * pad), (0, 0)), mode="edge")
        wrapped = ndimage.binary_closing(wrapped, disk)
        wrapped = ndimage.binary_opening(wrapped, disk)
        occupied = wrapped[2 * pad:-2 * pad, 2 * pad:-2 * pad]
    holes = ~occupied
    coverage = float(occupied.sum() / occupied.size)
    # hole cells back to 3D: centre of the cell at the median radius of its row's points
    row_radius = np.full(n_rows, r_mean)
    for r_i in np.unique(row):
        row_radius[r_i] = np.median(radius[row == r_i])
    hr, hc = np.nonzero(holes)
    th = (hc + 0.5) / n_cols * 2 * np.pi
    k = row_centre_sample(hr, n_rows, len(line.points) - 1)
    hole_pts = (line.points[k] + row_radius[hr, None] * (np.cos(th)[:, None] * nrm[k] + np.sin(th)[:, None] * bin_[k]))
    return Estimate(coverage, hole_pts, line.points, method)


class UnwrapMethod:
    """Baseline 3 as the paper ran it: unwrapping around the centerline of the shared network prediction.

    Parameters
    ----------
    model : path, optional
        Model of the prediction (default: the shipped one); shared with the
        other methods built on it in the same process.
    device : str
    tta : int
        Symmetries the shared prediction is averaged over (:mod:`colonbench.completion.symmetry`).
    """

    name = "unwrap"

    def __init__(self, model=None, device: str = "cpu", tta: int = 1):
        from colonbench.completion.method import prediction_version, shared_predictor

        self.predictor = shared_predictor(model, device, tta)
        self.version = f"{prediction_version(self.predictor)},{RASTER}"

    def estimate(self, points) -> Estimate:
        """Coverage, holes and centerline of one partial segment (mm)."""
        from colonbench.completion.method import on_prediction

        def unwrap_learned(pts, p):
            from colonbench.completion.planes import line_between, segment_planes

            cl = p.centerline_vox
            if len(cl) >= 2:  # the line the completion method reports: between the segment's planes
                cl = line_between(cl, segment_planes(cl, p.grid.to_voxel(pts)))
            return unwrap_coverage(pts, p.grid.to_mm(cl) if len(cl) else np.zeros((0, 3)), self.name)

        return on_prediction(self.predictor, points, "unwrap", unwrap_learned)


class UnwrapPCAMethod:
    """Baseline 3 as Ma et al. ran it: unwrapping around a straight axis, the points' first principal component."""

    name = "unwrap-pca"
    version = RASTER

    def estimate(self, points) -> Estimate:
        """Coverage, holes and (straight) centerline of one partial segment (mm)."""
        from colonbench.completion.method import check_cloud

        pts = check_cloud(points)
        return unwrap_coverage(pts, pca_axis(pts), self.name)
