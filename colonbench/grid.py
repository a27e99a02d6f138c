"""The segment-to-grid transform: where a 64^3 heatmap grid sits in millimetres.

A :class:`Grid` is a cube of ``size^3`` voxels with an isotropic voxel size,
placed by a 4x4 affine that maps a voxel index ``(i, j, k, 1)`` (voxel centres
at integer indices) to a point in mm in the input's frame, as in NIfTI.

:func:`fit_grid` computes it from the partial points alone, identically when
training data is made and when a method estimates: the grid axes are the
axes of the tube (:func:`tube_axes`: the axis is the direction the surface
normals are most perpendicular to, so a short, wide segment gets its axis
along the colon, not across it) or, for models trained before, the principal
axes of the points (:func:`principal_axes`); the points' bounding box in that
frame is centred in the grid, and the voxel size makes its longest side
(at least ``min_extent_mm``) span ``size - 1 - 2 * margin`` voxels. A 6 cm
segment of a 2 cm radius colon thus gets voxels of about 1.1-1.3 mm (the paper:
about 1 mm); a cloud that covers only part of its segment still gets a grid
wide enough for the whole segment.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from colonbench.errors import InputError

#: Heatmap grid side, voxels (the paper's 64^3).
GRID_SIZE = 64
#: Empty voxels kept between the partial points' bounding box and the grid border, on each side.
GRID_MARGIN = 4
#: Smallest side of the points' box the grid is fitted to, mm: a partial cloud that covers only part of
#: a segment still gets a grid that can hold the longest segment cut (7 cm).
GRID_MIN_EXTENT_MM = 70.0
#: Fewest points :func:`fit_grid` accepts.
MIN_POINTS = 10
#: How the grid axes are found: ``"tube"`` (:func:`tube_axes`) or ``"pca"`` (:func:`principal_axes`).
AXES = ("tube", "pca")
#: Neighbours of a point that its normal is estimated from (:func:`tube_axes`).
NORMAL_NEIGHBOURS = 24
#: Points :func:`tube_axes` estimates normals on at most (an even subsample of larger clouds).
NORMAL_POINTS = 3000
#: Below this ratio of the middle to the largest eigenvalue of the normals' scatter, the normals are
#: too alike (a patch of wall) to tell the axis: the axis is then taken in the plane they leave free.
FLAT_RATIO = 0.15


@dataclass(frozen=True)
class Grid:
    """A cubic voxel grid placed in millimetre space.

    Attributes
    ----------
    affine : (4, 4) float
        Voxel index ``(i, j, k, 1)`` -> point ``(x, y, z, 1)`` in mm. Its 3x3
        block is ``voxel_size * rotation.T``.
    size : int
        Voxels per side.
    """

    affine: np.ndarray
    size: int = GRID_SIZE

    @property
    def voxel_size(self) -> float:
        """Edge of one voxel, mm."""
        return float(np.linalg.norm(self.affine[:3, 0]))

    @property
    def rotation(self) -> np.ndarray:
        """(3, 3) rotation whose rows are the grid axes i, j, k in mm space."""
        return (self.affine[:3, :3] / self.voxel_size).T

    @property
    def inverse(self) -> np.ndarray:
        """(4, 4) affine from mm to continuous voxel index."""
        return np.linalg.inv(self.affine)

    def to_voxel(self, points) -> np.ndarray:
        """(n, 3) points in mm -> (n, 3) continuous voxel indices (voxel centres are integers)."""
        pts = np.asarray(points, dtype=float).reshape(-1, 3)
        inv = self.inverse
        return pts @ inv[:3, :3].T + inv[:3, 3]

    def to_mm(self, ijk) -> np.ndarray:
        """(n, 3) continuous voxel indices -> (n, 3) points in mm."""
        idx = np.asarray(ijk, dtype=float).reshape(-1, 3)
        return idx @ self.affine[:3, :3].T + self.affine[:3, 3]


def principal_axes(points) -> np.ndarray:
    """(3, 3) rotation whose rows are the principal axes of ``points``, largest variance first.

    Signs are made deterministic: each axis points towards the side with the
    larger third moment of the points, and the last axis is flipped if needed
    so that the rows form a right-handed frame (determinant +1).
    """
    pts = np.asarray(points, dtype=float)
    centred = pts - pts.mean(axis=0)
    cov = centred.T @ centred / max(len(pts), 1)
    _, vecs = np.linalg.eigh(cov)
    return _oriented(vecs[:, ::-1].T, centred)


def _oriented(axes: np.ndarray, centred: np.ndarray) -> np.ndarray:
    """Rows of ``axes`` signed towards their larger third moment of ``centred``, made right-handed."""
    axes = np.array(axes, dtype=float)
    skew = ((centred @ axes.T) ** 3).sum(axis=0)
    axes[skew < 0] *= -1
    if np.linalg.det(axes) < 0:
        axes[2] *= -1
    return axes


def point_normals(points, neighbours: int = NORMAL_NEIGHBOURS) -> np.ndarray:
    """Unit normals (sign arbitrary) of a surface point cloud by local PCA; (n, 3).

    The normal of a point is the smallest principal axis of its ``neighbours``
    nearest points.
    """
    from scipy.spatial import cKDTree

    pts = np.asarray(points, dtype=float)
    k = int(min(neighbours, len(pts)))
    _, idx = cKDTree(pts).query(pts, k=k)
    nb = pts[idx]                                                   # (n, k, 3)
    nb -= nb.mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", nb, nb)
    _, vecs = np.linalg.eigh(cov)
    return vecs[:, :, 0]


def even_subsample(points, max_points: int) -> np.ndarray:
    """At most ``max_points`` of the (n, 3) ``points``, every k-th in lexicographic (x, y, z) order.

    The order the points came in does not matter: the same cloud in any order
    gives the same subsample, so everything estimated from it (the grid's
    axes, the cloud's density) is a function of the cloud alone. Taking every
    k-th point in the file's order instead turned the grid by a fraction of a
    degree when the points were shuffled, and the completion method's coverage
    by 1.4 points on average (up to 10) on real-colon segments.
    """
    pts = np.asarray(points, dtype=float)
    step = max(1, int(np.ceil(len(pts) / max_points)))
    if step == 1:
        return pts
    return pts[np.lexsort(pts.T[::-1])[::step]]


def distinct_points(points) -> np.ndarray:
    """The distinct rows of the (n, 3) ``points``, in lexicographic (x, y, z) order.

    A cloud is taken as the set of its points: the same points in another
    order, or with some of them repeated (fragments merged, a mesh's shared
    vertices written once per face), give the same array, so that everything
    drawn from it (the thinning of a dense cloud) depends on the cloud alone.

    Parameters
    ----------
    points : (n, 3) float
        mm.

    Returns
    -------
    (m, 3) float
        m <= n.
    """
    pts = np.asarray(points, dtype=float)
    if len(pts) < 2:
        return pts
    pts = pts[np.lexsort(pts.T[::-1])]
    keep = np.ones(len(pts), bool)
    keep[1:] = np.any(pts[1:] != pts[:-1], axis=1)
    return pts[keep]


def tube_axes(points, neighbours: int = NORMAL_NEIGHBOURS, max_points: int = NORMAL_POINTS) -> np.ndarray:
    """(3, 3) rotation whose first row is the axis of the tube a partial surface cloud lies on.

    The wall of a tube has normals perpendicular to its axis, so the axis is
    the direction that minimises the sum of squared projections of the point
    normals: the smallest eigenvector of their scatter ``sum n n^T``. Unlike
    the cloud's largest spread, this holds for a segment that is wider than it
    is long, and for a cloud with one side missing. Fold flanks lean the
    normals towards the axis on both sides alike, which leaves the eigenvector
    where it is. When the normals are nearly all alike (a patch of wall, the
    middle eigenvalue below :data:`FLAT_RATIO` of the largest) they do not
    fix the axis, and it is taken as the direction of largest spread in the
    plane they leave free. The other two rows are the principal axes of the
    points across the axis, larger first. Signs follow :func:`principal_axes`.

    Parameters
    ----------
    points : (n, 3) float
        Surface points, mm.
    neighbours : int
        Points per local normal estimate.
    max_points : int
        Normals are estimated on an even subsample of at most this many points (:func:`even_subsample`).

    Returns
    -------
    (3, 3) float
        Rows: tube axis, then the cross-section axes; determinant +1.
    """
    pts = np.asarray(points, dtype=float)
    centred = pts - pts.mean(axis=0)
    sub = even_subsample(pts, max_points)
    if len(sub) < 2 * neighbours:
        return principal_axes(pts)
    normals = point_normals(sub, neighbours)
    vals, vecs = np.linalg.eigh(normals.T @ normals)
    if vals[1] < FLAT_RATIO * vals[2]:
        # one dominant normal: the axis lies in the plane it is perpendicular to, along the cloud
        free = vecs[:, :2].T
        spread = np.linalg.eigh(np.cov((centred @ free.T).T))[1][:, -1]
        axis = spread @ free
    else:
        axis = vecs[:, 0]
    return axes_around(axis, pts)


def axes_around(axis, points) -> np.ndarray:
    """(3, 3) rotation whose first row is ``axis`` (normalised) and whose other rows are the principal axes of
    ``points`` projected on the plane across it, larger first; signs as :func:`principal_axes`.

    The grid of a tube once its axis is known: :func:`tube_axes` finds it from the points' normals,
    :func:`colonbench.slab.context_rotation` from a known centerline.
    """
    pts = np.asarray(points, dtype=float)
    centred = pts - pts.mean(axis=0)
    axis = np.asarray(axis, dtype=float)
    axis = axis / np.linalg.norm(axis)
    across = centred - np.outer(centred @ axis, axis)
    _, cv = np.linalg.eigh(across.T @ across)
    second = cv[:, 2] - (cv[:, 2] @ axis) * axis
    second /= np.linalg.norm(second)
    return _oriented(np.stack([axis, second, np.cross(axis, second)]), centred)


def grid_axes(points, axes: str = "pca") -> np.ndarray:
    """The grid rotation of a cloud by method ``axes`` (one of :data:`AXES`)."""
    if axes == "tube":
        return tube_axes(points)
    if axes == "pca":
        return principal_axes(points)
    raise InputError(f"unknown grid axes {axes!r}; choose one of {list(AXES)}")


def check_points(points, what: str = "point cloud", min_points: int = MIN_POINTS) -> np.ndarray:
    """``points`` as a finite (n, 3) float array with n >= ``min_points``, or a clear :class:`InputError`."""
    try:
        pts = np.asarray(points, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{what}: not an array of numbers") from None
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise InputError(f"{what}: expected an (n, 3) array of x, y, z in mm, got shape {pts.shape}")
    if not np.all(np.isfinite(pts)):
        raise InputError(f"{what}: {int((~np.isfinite(pts).all(axis=1)).sum())} point(s) are NaN or infinite")
    if len(pts) < min_points:
        raise InputError(f"{what}: {len(pts)} point(s); at least {min_points} are needed to place a grid")
    return pts


def fit_grid(points, size: int = GRID_SIZE, margin: int = GRID_MARGIN, rotation=None,
             scale: float = 1.0, min_extent_mm: float = GRID_MIN_EXTENT_MM, axes: str = "pca") -> Grid:
    """The grid of a partial segment, from its points alone.

    Parameters
    ----------
    points : (n, 3) float
        Partial point cloud, mm.
    size : int
        Voxels per side.
    margin : int
        Voxels left free on each side of the points' bounding box.
    rotation : (3, 3) float, optional
        Grid axes as rows (default: :func:`grid_axes` of the points by ``axes``).
    scale : float
        Multiplies the voxel size (1 = fitted; > 1 leaves more room; used by
        scale augmentation).
    min_extent_mm : float
        The longest side of the points' box counts as at least this much.
    axes : {"pca", "tube"}
        How the rotation is found when none is given: ``"tube"`` (the tube's
        own axis, :func:`tube_axes`) or ``"pca"`` (the points' principal axes,
        what models trained before version 0.2 saw).

    Returns
    -------
    Grid
    """
    pts = check_points(points)
    if size < 2 * margin + 2:
        raise InputError(f"grid size {size} leaves no room inside a margin of {margin} voxels")
    rot = grid_axes(pts, axes) if rotation is None else np.asarray(rotation, dtype=float)
    if rot.shape != (3, 3) or not np.allclose(rot @ rot.T, np.eye(3), atol=1e-9):
        raise InputError("rotation must be a 3x3 orthonormal matrix")
    centre = pts.mean(axis=0)
    local = (pts - centre) @ rot.T
    lo, hi = local.min(axis=0), local.max(axis=0)
    extent = float((hi - lo).max())
    if extent <= 0:
        raise InputError("point cloud: all points coincide; no grid can be placed")
    extent = max(extent, float(min_extent_mm))
    voxel = extent / (size - 1 - 2 * margin) * float(scale)
    mid = (lo + hi) / 2.0
    affine = np.eye(4)
    affine[:3, :3] = voxel * rot.T
    affine[:3, 3] = centre + rot.T @ (mid - voxel * (size - 1) / 2.0)
    return Grid(affine, int(size))
