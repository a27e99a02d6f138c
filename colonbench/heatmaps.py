"""The paper's input and target heatmaps, defined once for data generation, training and inference.

For a voxel ``v`` of a :class:`~colonbench.grid.Grid`, with distances in voxels::

    H_input[v]  = tanh(0.2 d(v, S0))
    H_target[v] = tanh(0.2 d(v, S1)) / (tanh(0.2 d(v, S1)) + tanh(0.2 d(v, C)))

``S0`` is the voxelized partial surface (the voxels holding a partial point),
``S1`` the voxelized complete surface (every voxel the mesh passes through) and
``C`` the voxelized centerline. Distances are exact Euclidean distance
transforms (the ``edt`` package). The target is 0 on the surface, 1 on the
centerline and about 0.5 elsewhere; where both distances are 0 (a centerline
voxel on the surface, which only a degenerate segment has) it is set to 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import edt as _edt
import numpy as np

from colonbench.errors import InputError
from colonbench.grid import Grid

#: The 0.2 in tanh(0.2 d).
HEATMAP_SCALE = 0.2
#: Spacing of the points that voxelize meshes and polylines, voxels.
VOXELIZE_SPACING = 0.5


def distance_to(occupied: np.ndarray) -> np.ndarray:
    """Euclidean distance (voxels) from every voxel to the nearest occupied voxel.

    Parameters
    ----------
    occupied : (s, s, s) bool

    Returns
    -------
    (s, s, s) float32
        0 on occupied voxels.
    """
    if not occupied.any():
        raise InputError("nothing to measure distances to: no occupied voxel in the grid")
    # as uint8 (the same labels): edt runs a quarter faster on it than on bool
    free = np.ascontiguousarray(~np.asarray(occupied, dtype=bool)).view(np.uint8)
    return _edt.edt(free, black_border=False, parallel=1).astype(np.float32, copy=False)


def voxel_indices(grid: Grid, ijk: np.ndarray) -> tuple[np.ndarray, int]:
    """Round continuous voxel indices to voxels of the grid.

    Returns
    -------
    idx : (m, 3) int
        The voxels inside the grid (with repeats).
    outside : float
        Fraction of the inputs that fell outside (0 when there are none).
    """
    r = np.rint(ijk)
    # column by column: numpy reduces a short last axis slowly
    keep = (r[:, 0] >= 0) & (r[:, 0] < grid.size)
    for axis in (1, 2):
        keep &= (r[:, axis] >= 0) & (r[:, axis] < grid.size)
    return r[keep].astype(np.intp), float(1.0 - keep.mean()) if len(r) else 0.0


def occupancy(grid: Grid, idx: np.ndarray) -> np.ndarray:
    """(s, s, s) bool grid with the voxels ``idx`` (m, 3) set."""
    occ = np.zeros(grid.size ** 3, dtype=bool)
    idx = np.asarray(idx, dtype=np.intp)
    occ[(idx[:, 0] * grid.size + idx[:, 1]) * grid.size + idx[:, 2]] = True
    return occ.reshape((grid.size,) * 3)


def voxelize_points(grid: Grid, points) -> tuple[np.ndarray, int]:
    """The voxels holding at least one point (mm); returns (occupancy, fraction of points outside the grid)."""
    idx, outside = voxel_indices(grid, grid.to_voxel(points))
    return occupancy(grid, idx), outside


def triangle_lattice(a: np.ndarray, b: np.ndarray, c: np.ndarray, spacing: float) -> np.ndarray:
    """Points on triangles no farther than ``spacing`` apart along every edge direction.

    Each triangle is cut into ``n^2`` similar triangles, ``n`` the smallest
    integer making its longest edge / n <= ``spacing``; the lattice vertices
    are returned, each ``w a + u b + v c`` in that order of operations.
    Deterministic, so the voxelization of a mesh is too.

    Parameters
    ----------
    a, b, c : (f, 3) float
        Triangle corners.
    spacing : float
        Same unit as the corners.

    Returns
    -------
    (m, 3) float
        Grouped by subdivision ``n``, then by lattice vertex (every triangle's
        first vertex, then every triangle's second, ...): a set of points, as
        voxelization takes them.
    """
    edges = np.stack([np.linalg.norm(b - a, axis=1), np.linalg.norm(c - b, axis=1),
                      np.linalg.norm(a - c, axis=1)], axis=1)
    n_sub = np.maximum(np.ceil(edges.max(axis=1) / spacing), 1).astype(np.int64)
    out = []
    for n in np.unique(n_sub):
        sel = n_sub == n
        i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
        ok = (i + j) <= n
        u = i[ok] / n
        v = j[ok] / n
        w = 1.0 - u - v
        corners_a, corners_b, corners_c = a[sel], b[sel], c[sel]
        # one lattice vertex at a time over contiguous (f, 3) arrays: 2x faster than broadcasting to (f, k, 3)
        pts = np.empty((len(u), len(corners_a), 3))
        term = np.empty(corners_a.shape)  # float64, as the weights make any corners
        for k in range(len(u)):
            np.multiply(w[k], corners_a, out=pts[k])
            pts[k] += np.multiply(u[k], corners_b, out=term)
            pts[k] += np.multiply(v[k], corners_c, out=term)
        out.append(pts.reshape(-1, 3))
    return np.concatenate(out) if out else np.zeros((0, 3))


def voxelize_mesh(grid: Grid, vertices, faces) -> tuple[np.ndarray, int]:
    """The voxels a triangle mesh (mm) passes through; returns (occupancy, fraction of its area outside the grid)."""
    verts = grid.to_voxel(vertices)
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    pts = triangle_lattice(verts[faces[:, 0]], verts[faces[:, 1]], verts[faces[:, 2]], VOXELIZE_SPACING)
    idx, outside = voxel_indices(grid, pts)
    return occupancy(grid, idx), outside


def densify_polyline(points: np.ndarray, spacing: float) -> np.ndarray:
    """(m, 3) polyline resampled so that consecutive points are at most ``spacing`` apart (vertices kept)."""
    pts = np.asarray(points, dtype=float).reshape(-1, 3)
    if len(pts) < 2:
        return pts
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    n = np.maximum(np.ceil(seg / spacing), 1).astype(np.int64)
    t = np.concatenate([np.arange(k) / k for k in n])
    start = np.repeat(np.arange(len(seg)), n)
    dense = pts[start] + t[:, None] * (pts[start + 1] - pts[start])
    return np.vstack([dense, pts[-1:]])


def voxelize_polyline(grid: Grid, points) -> tuple[np.ndarray, int]:
    """The voxels a polyline (mm) passes through; returns (occupancy, fraction of its length outside the grid)."""
    dense = densify_polyline(grid.to_voxel(points), VOXELIZE_SPACING)
    idx, outside = voxel_indices(grid, dense)
    return occupancy(grid, idx), outside


def input_heatmap(d_partial):
    """``tanh(0.2 d(v, S0))`` from the distance (voxels) to the partial surface.

    ``d_partial`` is a float32 numpy array or torch tensor (any shape); the
    result is of the same kind, so training on a GPU uses this same formula.
    """
    return (d_partial * HEATMAP_SCALE).tanh() if hasattr(d_partial, "tanh") else np.tanh(
        np.float32(HEATMAP_SCALE) * d_partial)


def target_heatmap(d_surface, d_centerline):
    """``t_S / (t_S + t_C)`` with ``t = tanh(0.2 d)``, from distances (voxels) to the complete surface and centerline.

    Numpy arrays or torch tensors of one shape (float32); 0 where both distances are 0.
    """
    ts, tc = input_heatmap(d_surface), input_heatmap(d_centerline)
    den = ts + tc
    if hasattr(den, "tanh"):  # torch
        return (ts / den.clamp_min(1e-30)).masked_fill(den <= 0, 0.0)
    out = np.zeros_like(ts)
    np.divide(ts, den, out=out, where=den > 0)
    return out


def heatmaps_from_occupancy(s0, s1, c, distance=distance_to):
    """Input and target heatmaps from the partial-surface, surface and centerline occupancy grids.

    Parameters
    ----------
    s0, s1, c : bool arrays of one shape
        Voxels holding a partial point, voxels the complete surface passes
        through, voxels the centerline passes through.
    distance : callable
        Occupancy -> distance (voxels) to its nearest occupied voxel:
        :func:`distance_to` here; training on a GPU passes its own
        (:func:`colonbench.completion.packdata.distance_to`, torch tensors).

    Returns
    -------
    input, target
        float32, of the kind ``distance`` returns.
    """
    return input_heatmap(distance(s0)), target_heatmap(distance(s1), distance(c))


@dataclass
class Heatmaps:
    """Input and target heatmaps of one sample, and how much geometry fell outside the grid.

    Attributes
    ----------
    input, target : (s, s, s) float32
    outside : dict
        Fraction of each geometry that fell outside the grid (and is missing
        from the heatmaps): ``partial`` (of the points), ``complete`` (of the
        surface, by lattice points), ``centerline`` (of its length).
    """

    input: np.ndarray
    target: np.ndarray
    outside: dict


def input_from_points(grid: Grid, partial) -> tuple[np.ndarray, int]:
    """The input heatmap of a partial cloud (mm): what a method computes at inference.

    Returns
    -------
    heatmap : (s, s, s) float32
    outside : float
        Fraction of the points that fell outside the grid.
    """
    occ, outside = voxelize_points(grid, partial)
    return input_heatmap(distance_to(occ)), outside


@dataclass
class Occupancy:
    """The three occupancy grids a sample's heatmaps are functions of (:func:`heatmaps_from_occupancy`).

    Attributes
    ----------
    s0, s1, c : (s, s, s) bool
        Voxels holding a partial point, voxels the complete surface passes
        through, voxels the centerline passes through.
    outside : dict
        Fraction of each geometry that fell outside the grid, as in :class:`Heatmaps`.
    """

    s0: np.ndarray
    s1: np.ndarray
    c: np.ndarray
    outside: dict

    @property
    def grids(self) -> dict:
        """``s0``, ``s1``, ``c`` by name."""
        return {"s0": self.s0, "s1": self.s1, "c": self.c}

    def heatmaps(self) -> Heatmaps:
        """The sample's input and target heatmaps, float32."""
        h_in, h_t = heatmaps_from_occupancy(self.s0, self.s1, self.c)
        return Heatmaps(h_in, h_t, dict(self.outside))


def sample_occupancy(grid: Grid, partial, vertices, faces, centerline) -> Occupancy:
    """The occupancy grids of one sample (arguments as :func:`sample_heatmaps`)."""
    occ_p, out_p = voxelize_points(grid, partial)
    occ_s, out_s = voxelize_mesh(grid, vertices, faces)
    occ_c, out_c = voxelize_polyline(grid, centerline)
    return Occupancy(occ_p, occ_s, occ_c, {"partial": out_p, "complete": out_s, "centerline": out_c})


def empty_grids(grids: dict) -> list:
    """The names of the grids (bool or bit-packed) with no occupied voxel: none can have a heatmap
    (:func:`distance_to`)."""
    return [name for name, grid in grids.items() if not np.any(grid)]


def pack_occupancy(occupied: np.ndarray) -> np.ndarray:
    """(s, s, s) bool -> (s^3 / 8,) uint8: ``numpy.packbits`` in C order (how shards and packs store a grid)."""
    return np.packbits(np.asarray(occupied, dtype=bool).ravel())


def unpack_occupancy(bits: np.ndarray, size: int) -> np.ndarray:
    """(..., s^3 / 8) uint8 -> (..., s, s, s) bool: the inverse of :func:`pack_occupancy`."""
    bits = np.asarray(bits, dtype=np.uint8)
    return np.unpackbits(bits, axis=-1).astype(bool).reshape(bits.shape[:-1] + (size,) * 3)


def sample_heatmaps(grid: Grid, partial, vertices, faces, centerline) -> Heatmaps:
    """Input and target heatmaps of one sample.

    Parameters
    ----------
    grid : Grid
        From :func:`colonbench.grid.fit_grid` on ``partial``.
    partial : (n, 3) float
        Partial points, mm.
    vertices : (v, 3) float
    faces : (f, 3) int
        The complete segment surface, mm.
    centerline : (m, 3) float
        GT centerline polyline inside the segment, mm.
    """
    return sample_occupancy(grid, partial, vertices, faces, centerline).heatmaps()
