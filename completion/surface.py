"""The completed surface from a (predicted) target heatmap, its holes and the coverage.

The target heatmap has its minimum (0) on the surface, larger values on both
sides, so the surface is not an iso-surface of it. The paper re-signs the
field near the surface: ``v_new = d(s, C) - d(v, C)`` with ``s`` the surface
voxel closest to ``v`` and ``C`` the centerline, positive inside the tube,
negative outside, and runs marching cubes on its zero crossing.

With ``s`` a single voxel the field is 0 on every surface voxel, and a
voxelized surface is one to two voxels thick, so the zero level would sit on
one face of that shell or the other (half a voxel, ~2.5 % of a 20 mm radius).
We therefore take ``d(s, C)`` as a local mean over the surface voxels near
``v`` (a Gaussian-weighted average of the centerline distance of the voxels
below the surface threshold, weighted by how far below it they are). On a
cylinder this is the wall radius, and the zero crossing is the wall, with
sub-voxel precision (tested: area within 2 %).

Marching cubes runs within a band of 3 voxels around the surface voxels, so
where the surface voxels stop (a free edge of the shell: the rim of a real
colon's fold, a stretch the heatmap leaves out) the zero crossing runs on past
them as a flap, and between the folds of a collapsed colon the local mean
puts a ghost wall between two real ones. Neither is on the heatmap's surface
and neither has partial points, so both counted as holes (on the real test
colon the GT heatmap's coverage came out 5.5 points low). Faces with a
vertex where the heatmap is above :data:`SHELL_LEVEL` are dropped
(:func:`clip_to_shell`).

The colon is a closed tube: every direction across the centerline meets the
wall. Where the predicted heatmap holds no surface voxel along a ray from
the centerline (a large unobserved area whose surface the network left out),
the wall is missing from the completed mesh, and without it the coverage
came out high. :func:`colonbench.completion.gaps.wall_gaps` adds a patch of hole surface there, at the
wall distance of the other rays at that station.

Holes follow the paper: a vertex of the completed mesh farther than
sqrt(2)/2 voxel from every partial point is a hole vertex. Coverage = the area
of the observed part of the mesh / the area of the mesh, where each triangle
counts by the share of its vertices that are observed.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree
from skimage.measure import marching_cubes

from colonbench.grid import Grid, even_subsample
from colonbench.heatmaps import distance_to, voxelize_polyline
from colonbench.meshes import triangle_areas

#: Voxels below this value are surface voxels.
SURFACE_THRESHOLD = 0.15
#: Faces with a vertex where the (trilinearly interpolated) heatmap is above this are dropped: off the
#: surface the heatmap says is there. On an exact heatmap of a 15-voxel radius it is 0.2 about 1.3
#: voxels from the surface. Chosen among 0.2, 0.25, 0.3 and a 1-voxel distance to the surface voxels
#: on validation data (docs/method.md step 4).
SHELL_LEVEL = 0.2
#: Marching cubes runs within this many voxels of a surface voxel.
BAND_VOXELS = 3.0
#: Scale of the local mean of d(s, C), voxels.
WALL_SIGMA = 1.0
#: The paper's hole distance: sqrt(2)/2 voxel.
HOLE_DISTANCE = np.sqrt(2.0) / 2.0
#: Where the cloud is too sparse for the paper's distance, a vertex is a hole only if an observed surface
#: of the cloud's local density would leave a gap that wide this rarely (Poisson sampling).
FALSE_HOLE_RATE = 0.01
#: Neighbours of a partial point that its local density is estimated from.
DENSITY_NEIGHBOURS = 8
#: The cloud's density is the median over an even subsample of at most this many of its points.
DENSITY_POINTS = 2000
#: Neighbours of a partial point that its wall thickness is estimated from (:func:`wall_thickness`).
THICKNESS_NEIGHBOURS = 16


def resigned_field(heatmap: np.ndarray, centerline_vox: np.ndarray, threshold: float = SURFACE_THRESHOLD,
                   band: float = BAND_VOXELS, sigma: float = WALL_SIGMA) -> tuple[np.ndarray, np.ndarray]:
    """The field ``d(s, C) - d(v, C)`` near the surface, and the mask where it is defined.

    Parameters
    ----------
    heatmap : (S, S, S) float
    centerline_vox : (m, 3) float
        Centerline in continuous voxel indices.

    Returns
    -------
    field : (S, S, S) float32
        Positive inside, negative outside, zero on the wall, within the mask
        and wherever a surface voxel is within the Gaussian's reach; elsewhere
        (never read by marching cubes) ``-(band + 1)``.
    mask : (S, S, S) bool
        Voxels within ``band`` of a surface voxel.
    """
    h = np.asarray(heatmap, dtype=np.float32)
    surface = h < threshold
    if not surface.any() or len(centerline_vox) == 0:
        return np.zeros_like(h), np.zeros(h.shape, bool)
    # the centerline is voxelized as for the training targets, on a grid whose voxel index is the coordinate
    line, _ = voxelize_polyline(Grid(np.eye(4), h.shape[0]), centerline_vox)
    if not line.any():
        return np.zeros_like(h), np.zeros(h.shape, bool)
    d_c = distance_to(line)
    weight = np.where(surface, threshold - h, 0.0).astype(np.float32)
    num = ndimage.gaussian_filter(weight * d_c, sigma, mode="constant")
    den = ndimage.gaussian_filter(weight, sigma, mode="constant")
    near = distance_to(surface) <= band
    valid = den > 1e-6
    mask = near & valid
    wall = np.where(valid, num / np.maximum(den, 1e-12), 0.0)
    # outside the band the field keeps its sign (the wall estimate of the voxel, or that of its nearest
    # valid neighbours) with a magnitude beyond the band, so marching cubes sees no crossing at the band's edge
    read = ndimage.binary_dilation(mask, structure=np.ones((3, 3, 3), bool))   # the voxels marching cubes reads
    wall = np.where(valid, wall, _nearest_valid_mean(wall, valid, read & ~valid))
    outside = np.where(valid | read, np.sign(wall - d_c), -1.0) * (band + 1.0)
    return np.where(mask, wall - d_c, outside).astype(np.float32), mask


def _nearest_valid_mean(values: np.ndarray, valid: np.ndarray, where: np.ndarray) -> np.ndarray:
    """At the voxels ``where``, the mean of ``values`` over their nearest ``valid`` neighbours; 0 elsewhere.

    Neighbours are the 26 around a voxel, nearest first: the 6 across a face,
    then the 12 across an edge, then the 8 across a corner; the first of those
    shells with a valid voxel gives the mean. A voxel of ``where`` with no
    valid neighbour gets 0. Marching cubes reads the field only within a voxel
    of its mask, and every such voxel has a valid neighbour, so this replaces a
    distance transform with indices over the whole grid (a quarter of the
    surface step's time).
    """
    out = np.zeros_like(values)
    idx = np.argwhere(where)
    hi = np.array(values.shape) - 1
    todo = np.ones(len(idx), bool)
    offsets = np.array([o for o in np.ndindex(3, 3, 3) if o != (1, 1, 1)]) - 1
    for shell in (1, 2, 3):
        total = np.zeros(len(idx))
        count = np.zeros(len(idx), int)
        for off in offsets[(offsets ** 2).sum(axis=1) == shell]:
            nb = idx + off
            nbc = np.clip(nb, 0, hi)
            hit = todo & np.all(nb == nbc, axis=1) & valid[tuple(nbc.T)]
            total[hit] += values[tuple(nbc[hit].T)]
            count[hit] += 1
        done = count > 0
        out[tuple(idx[done].T)] = total[done] / count[done]
        todo &= ~done
    return out


def extract_mesh(field: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Marching cubes on the zero crossing of ``field`` inside ``mask``; (vertices in voxels, faces)."""
    if mask.sum() < 8 or field[mask].min() >= 0 or field[mask].max() <= 0:
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
    verts, faces, _, _ = marching_cubes(field, level=0.0, mask=mask, allow_degenerate=False)
    return verts.astype(np.float64), faces.astype(np.int64)


def keep_faces(vertices: np.ndarray, faces: np.ndarray, keep_f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The mesh of the faces where ``keep_f`` is true, without the vertices no kept face uses."""
    used = np.unique(faces[keep_f])
    remap = np.full(len(vertices), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    return vertices[used], remap[faces[keep_f]]


def clip_to_shell(vertices: np.ndarray, faces: np.ndarray, heatmap: np.ndarray,
                  level: float = SHELL_LEVEL) -> tuple[np.ndarray, np.ndarray]:
    """Drop the faces with a vertex where the heatmap, trilinearly interpolated, is above ``level``.

    Marching cubes runs on the re-signed field in a band around the surface
    voxels, so it draws what the heatmap does not hold: flaps past the
    shell's free edges and ghost walls between close folds, 1 to 3.5 voxels
    off the surface, where the heatmap rises towards its 0.5 of the lumen and
    the outside. A weak surface of a prediction (0.15-0.2) is kept.
    """
    if len(faces) == 0:
        return vertices, faces
    h = ndimage.map_coordinates(np.asarray(heatmap, dtype=np.float32), vertices.T, order=1, mode="nearest")
    return keep_faces(vertices, faces, (h <= level)[faces].all(axis=1))


def sparse_reach(partial_vox: np.ndarray, false_hole_rate: float = FALSE_HOLE_RATE,
                 neighbours: int = DENSITY_NEIGHBOURS, tree=None) -> float:
    """The gap an observed surface sampled like the cloud leaves this rarely between its points, voxels.

    The cloud's density ``rho`` is :func:`cloud_density` (points per
    voxel^2). On a surface sampled as a Poisson process
    of density ``rho`` a disc of radius ``d`` holds no point with probability
    ``exp(-rho pi d^2)``, so a point of the observed surface is farther than
    ``sqrt(ln(1 / rate) / (pi rho))`` from every sample only with probability
    ``rate``.
    """
    rho = cloud_density(partial_vox, neighbours, tree)
    if rho == 0:
        return float("inf")
    return float(np.sqrt(np.log(1.0 / false_hole_rate) / (np.pi * rho)))


def cloud_density(points: np.ndarray, neighbours: int = DENSITY_NEIGHBOURS, tree=None) -> float:
    """Points per unit^2 of the surface a cloud samples (points/mm^2 for a cloud in mm).

    The local density at a point is ``k / (pi r_k^2)``, ``r_k`` the distance to its k-th nearest neighbour;
    the cloud's is the median over an even subsample of at most :data:`DENSITY_POINTS` of its points
    (:func:`colonbench.grid.even_subsample`), which outliers, a second layer and hole borders barely move.
    0 for fewer than two points.

    Parameters
    ----------
    points : (n, 3) float
    neighbours : int
        k.
    tree : scipy.spatial.cKDTree, optional
        A tree of ``points``, when the caller has one.
    """
    k = int(min(neighbours, len(points) - 1))
    if k < 1:
        return 0.0
    tree = cKDTree(points) if tree is None else tree
    r_k = tree.query(even_subsample(points, DENSITY_POINTS), k=k + 1)[0][:, -1]
    return float(k / (np.pi * max(float(np.median(r_k)), 1e-9) ** 2))


def wall_thickness(points: np.ndarray, neighbours: int = THICKNESS_NEIGHBOURS, tree=None) -> np.ndarray:
    """Each point's local wall thickness: the standard deviation of its nearest points along their normal.

    Parameters
    ----------
    points : (n, 3) float
        A partial cloud (any unit; voxels in the steps).
    neighbours : int
        Points (the point itself among them) the spread is measured over.
    tree : scipy.spatial.cKDTree, optional
        A tree of ``points``, when the caller has one.

    Returns
    -------
    (n,) float
        The square root of the smallest eigenvalue of the neighbours' covariance, in the points' unit: about 0
        on a clean thin surface (its curvature adds ``r^2 / (2 sqrt(3) R)`` over a neighbourhood of radius ``r`` on
        a wall of radius ``R``), the noise's sigma on a noisy one, and half the gap of a doubled wall.
    """
    k = int(min(neighbours, len(points)))
    if k < 4:
        return np.zeros(len(points))
    tree = cKDTree(points) if tree is None else tree
    near = points[tree.query(points, k=k)[1]]
    centred = near - near.mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", centred, centred) / k
    return np.sqrt(np.maximum(np.linalg.eigvalsh(cov)[:, 0], 0.0))


def hole_vertices(vertices: np.ndarray, partial_vox: np.ndarray, distance: float = HOLE_DISTANCE,
                  false_hole_rate: float | None = FALSE_HOLE_RATE, thickness: float = 0.0) -> np.ndarray:
    """(v,) bool: vertices farther than their hole distance (voxels) from every partial point (voxels).

    The hole distance is the paper's ``distance`` (sqrt(2)/2 voxel), widened
    to :func:`sparse_reach` when the cloud is too sparse for it: a cloud of 0.5
    points/mm^2 leaves gaps of 1.7 mm between its points, and the paper's
    distance (about 1 mm) would call them holes. At the paper's 2 points/mm^2
    and voxels of 1.2 mm or more the reach is below the paper's distance and
    changes nothing. ``false_hole_rate=None`` keeps the paper's distance alone. ``thickness`` ``c``: a vertex
    is observed when its nearest point lies within that distance plus ``c`` times the point's
    :func:`wall_thickness`.
    """
    if len(vertices) == 0:
        return np.zeros(0, bool)
    if len(partial_vox) == 0:
        return np.ones(len(vertices), bool)
    tree = cKDTree(partial_vox)
    if false_hole_rate is not None:
        distance = max(distance, sparse_reach(partial_vox, false_hole_rate, tree=tree))
    if not (np.isfinite(thickness) and thickness >= 0):
        raise ValueError(f"thickness must be a finite number >= 0, got {thickness!r}")
    if not thickness:
        d, _ = tree.query(vertices, k=1, distance_upper_bound=distance * 1.0001)
        return ~(d <= distance)
    allowed = distance + thickness * wall_thickness(partial_vox, tree=tree)
    d, i = tree.query(vertices, k=1, distance_upper_bound=float(allowed.max()) * 1.0001)
    found = i < len(partial_vox)
    observed = np.zeros(len(vertices), bool)
    observed[found] = d[found] <= allowed[i[found]]
    return ~observed


def mesh_coverage(vertices: np.ndarray, faces: np.ndarray, hole: np.ndarray) -> float:
    """Observed area / total area, each triangle weighted by its share of observed vertices."""
    if len(faces) == 0:
        return float("nan")
    area = triangle_areas(vertices, faces)
    observed = (~hole[faces]).mean(axis=1)
    total = area.sum()
    return float((area * observed).sum() / total) if total > 0 else float("nan")


