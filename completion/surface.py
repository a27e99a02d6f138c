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
came out high. :func:`wall_gaps` adds a patch of hole surface there, at the
wall distance of the other rays at that station.

Holes follow the paper: a vertex of the completed mesh farther than
sqrt(2)/2 voxel from every partial point is a hole vertex. Coverage = the area
of the observed part of the mesh / the area of the mesh, where each triangle
counts by the share of its vertices that are observed.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree
from skimage.measure import marching_cubes

from colonbench.grid import Grid, even_subsample
from colonbench.heatmaps import distance_to, voxelize_polyline
from colonbench.meshes import triangle_areas
from colonbench.polyline import resample

#: Revision of the steps after the network, part of the methods' versions: 1 the paper's, 2 the sparse
#: clouds' hole distance, 3 the cut rims, 4 the shell level, 5 the wall gaps, 6 the centerline's ends on the
#: lumen's far ends and the cut rims held where the line runs past them, 7 an end with no cut rim pushed out to
#: the cloud's extent, 8 the wall gaps' stations run on from the line's ends to planes beyond them, 9 clouds
#: denser than 3 points/mm^2 thinned to 2 before the method runs (:func:`colonbench.completion.method.thin_dense`),
#: 10 a cloud taken as its distinct points in lexicographic order before it is thinned (the thinning's draw
#: depended on the order of the points, and repeated points counted in the cloud's density).
STEPS_VERSION = "10"
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
#: Faces closer than this to an end plane are dropped, voxels.
END_INSET = 1.0
#: The end planes' normals are fitted to the centerline's points this far from each end, voxels.
END_REACH = 5.0
#: Cut rims (:func:`rim_planes`): points within this distance of a supporting plane touch it, voxels ...
RIM_BAND = 1.5
#: ... planes within this angle of the centerline's end tangent are tried, degrees ...
RIM_CAP_DEG = 60.0
#: ... this many of them ...
RIM_DIRECTIONS = 300
#: ... and a rim must fill this share of the sectors around the centerline's end.
RIM_MIN_SHARE = 0.5
#: Sectors around the centerline's end that a rim is counted in.
RIM_SECTORS = 24
#: Each end's rim is searched among the points nearest to this share of the centerline at that end.
RIM_END_SHARE = 0.35
#: The supporting plane lies at the cloud's this-many-th farthest point (a few outliers do not hold it).
RIM_OUTLIERS = 3
#: Fewer points than this (near an end, or touching a plane) are no rim.
RIM_MIN_POINTS = 50
RIM_MIN_TOUCHING = 20
#: The rim's plane is refined this many times by least squares, each fit within this angle of the
#: winning direction (degrees) ...
RIM_REFINE = 3
RIM_FIT_DEG = 15.0
#: The rim replaces the centerline's end plane where the line ends at least this far inside or past it, voxels.
RIM_BEYOND = 1.0


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


@dataclass
class Completion:
    """A completed segment in voxel coordinates of its grid.

    Attributes
    ----------
    vertices : (v, 3) float
        Completed mesh vertices, continuous voxel indices.
    faces : (f, 3) int
    hole : (v,) bool
        Vertices farther than the hole distance from the partial cloud.
    coverage : float
        Observed area / total area of the completed mesh (NaN if the mesh is empty).
    planes : list of (point, inward normal)
        The planes the mesh was clipped at (the segment's ends).
    """

    vertices: np.ndarray
    faces: np.ndarray
    hole: np.ndarray
    coverage: float
    planes: list = field(default_factory=list)


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


def _keep_faces(vertices: np.ndarray, faces: np.ndarray, keep_f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
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
    return _keep_faces(vertices, faces, (h <= level)[faces].all(axis=1))


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


def hole_vertices(vertices: np.ndarray, partial_vox: np.ndarray, distance: float = HOLE_DISTANCE,
                  false_hole_rate: float | None = FALSE_HOLE_RATE) -> np.ndarray:
    """(v,) bool: vertices farther than their hole distance (voxels) from every partial point (voxels).

    The hole distance is the paper's ``distance`` (sqrt(2)/2 voxel), widened
    to :func:`sparse_reach` when the cloud is too sparse for it: a cloud of 0.5
    points/mm^2 leaves gaps of 1.7 mm between its points, and the paper's
    distance (about 1 mm) would call them holes. At the paper's 2 points/mm^2
    and voxels of 1.2 mm or more the reach is below the paper's distance and
    changes nothing. ``false_hole_rate=None`` keeps the paper's distance alone.
    """
    if len(vertices) == 0:
        return np.zeros(0, bool)
    if len(partial_vox) == 0:
        return np.ones(len(vertices), bool)
    tree = cKDTree(partial_vox)
    if false_hole_rate is not None:
        distance = max(distance, sparse_reach(partial_vox, false_hole_rate, tree=tree))
    d, _ = tree.query(vertices, k=1, distance_upper_bound=distance * 1.0001)
    return ~(d <= distance)


def mesh_coverage(vertices: np.ndarray, faces: np.ndarray, hole: np.ndarray) -> float:
    """Observed area / total area, each triangle weighted by its share of observed vertices."""
    if len(faces) == 0:
        return float("nan")
    area = triangle_areas(vertices, faces)
    observed = (~hole[faces]).mean(axis=1)
    total = area.sum()
    return float((area * observed).sum() / total) if total > 0 else float("nan")


def end_planes(centerline_vox: np.ndarray, reach: float = END_REACH) -> list[tuple[np.ndarray, np.ndarray]]:
    """The segment's two end planes: (point, inward normal) at each end of the centerline.

    The normal is the principal direction of the centerline's points between
    1 and ``1 + reach`` voxels from the end (arc length), pointed inwards: a
    least-squares end tangent that leaves out the end point itself. The end
    point is a voxel of the ridge, kept in place while the line is smoothed,
    so the line curls into it; the direction from it to a single point 3
    voxels along (our first version) turned with that wobble, and on a curled
    end of a wide segment the plane clipped away most of the mesh.
    """
    c = np.asarray(centerline_vox, dtype=float)
    if len(c) < 2:
        return []
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(c, axis=0), axis=1))])
    planes = []
    from_end = {0: s, -1: s[-1] - s}
    for end in (0, -1):
        d = from_end[end]
        near = (d >= 1.0) & (d <= 1.0 + reach)
        pts = c[near] if near.sum() >= 3 else c[d <= 1.0 + reach]
        inward = pts.mean(axis=0) - c[end]
        if len(pts) >= 3:
            axis = np.linalg.svd(pts - pts.mean(axis=0), full_matrices=False)[2][0]
            n = axis if axis @ inward >= 0 else -axis
        else:
            n = inward
        if np.linalg.norm(n) > 0:
            planes.append((c[end], n / np.linalg.norm(n)))
    return planes


def _bases(axes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(d, 3) each: two unit vectors that make a right-handed orthonormal frame with each (d, 3) unit axis."""
    ref = np.where(np.abs(axes[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    u = np.cross(axes, ref)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    return u, np.cross(axes, u)


def cap_directions(axis: np.ndarray, max_deg: float, n: int) -> np.ndarray:
    """(n, 3) unit vectors spread evenly (a Fibonacci spiral) over the cap within ``max_deg`` of ``axis``."""
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    (u,), (v,) = _bases(a[None])
    i = np.arange(n) + 0.5
    z = 1.0 - (1.0 - np.cos(np.radians(max_deg))) * i / n
    r = np.sqrt(np.clip(1.0 - z * z, 0.0, None))
    phi = np.pi * (1.0 + np.sqrt(5.0)) * i
    return z[:, None] * a + (r * np.cos(phi))[:, None] * u + (r * np.sin(phi))[:, None] * v


def rim_planes(centerline_vox: np.ndarray, partial_vox: np.ndarray, band: float = RIM_BAND,
               cap_deg: float = RIM_CAP_DEG, min_share: float = RIM_MIN_SHARE) -> list[tuple[np.ndarray, np.ndarray]]:
    """The segment's cutting planes found from its cloud's cut rims, where they are seen (voxels).

    A segment is cut from the colon by two planes, so where an end was
    observed the partial cloud stops there in a rim of points all round the
    tube, in one plane: of the cloud's supporting planes (all its points on
    one side) at that end, the cut is the one that touches it all round. The
    estimated centerline's end (:func:`end_planes`) misses it: the network's
    ridge fades before the segment ends (on the real colon its line ends a
    median 9 mm short of the cut, its end tangent 32 degrees off), and
    the mesh between the two was clipped away.

    At each end the cloud's points whose nearest centerline point lies in the
    last :data:`RIM_END_SHARE` of its length are searched: for
    :data:`RIM_DIRECTIONS` outward directions within ``cap_deg`` of the end
    tangent, the supporting plane (at the :data:`RIM_OUTLIERS`-th farthest
    point, so that a few outliers do not hold it) and the points within
    ``band`` voxels of it. The direction whose touching points fill the most of
    :data:`RIM_SECTORS` sectors around the centerline's end wins (then the most
    points): a plane touching the side wall along a strip has many points
    but in few sectors. The directions are about 6 degrees apart, so this
    coarse search counts the points within twice ``band``. The plane is then
    fitted to its touching points by least squares, and its own supporting
    plane's points within ``band`` refitted, :data:`RIM_REFINE` times (each fit
    within :data:`RIM_FIT_DEG` of the winning direction). The rim is accepted
    if its points fill at least ``min_share`` of the sectors and it lies more
    than :data:`RIM_BEYOND` beyond or before the line's end (where the line
    reaches the cut, its own plane is as good; where the line runs on past it,
    into a lumen the network continued beyond the cut, the cut holds: steps
    version 6). Otherwise, an unobserved or ragged end, the end keeps
    :func:`end_planes`' plane, pushed out along its normal to the cloud's
    extent where the cloud runs on past it (:func:`pushed_out`, steps version 7).

    Returns
    -------
    list of (point, inward unit normal), one per end (as :func:`end_planes`).
    """
    planes = end_planes(centerline_vox)
    pts = np.asarray(partial_vox, float)
    if len(planes) != 2 or len(pts) < RIM_MIN_POINTS:
        return planes
    dense = resample(np.asarray(centerline_vox, float), 0.25)
    _, nearest = cKDTree(dense).query(pts)
    out = []
    for k, (point, normal) in enumerate(planes):
        near = nearest <= RIM_END_SHARE * len(dense) if k == 0 else nearest >= (1 - RIM_END_SHARE) * len(dense)
        x = pts[near]
        rim = _rim_plane(point, normal, x, band, cap_deg, min_share)
        out.append(pushed_out(point, normal, x) if rim is None else rim)
    return out


def _rim_plane(point: np.ndarray, normal: np.ndarray, x: np.ndarray, band: float, cap_deg: float,
               min_share: float) -> tuple[np.ndarray, np.ndarray] | None:
    """One end's plane from its cut rim (:func:`rim_planes`), or None where no rim is seen there.

    ``point``, ``normal``: the line's end plane (:func:`end_planes`); ``x`` (n, 3): the cloud's points at
    that end, voxels.
    """
    if len(x) < RIM_MIN_POINTS:
        return None
    # coarse: the directions are ~6 degrees apart, so the touching band is twice as wide
    dirs = cap_directions(-normal, cap_deg, RIM_DIRECTIONS)
    proj = dirs @ x.T                                           # (directions, points)
    touch = proj > _kth_largest(proj, RIM_OUTLIERS)[:, None] - 2 * band
    count = touch.sum(axis=1)
    touch[count < RIM_MIN_TOUCHING] = False
    sectors = _sectors(x - point, dirs, touch)
    if not sectors.any():
        return None
    best = int(np.lexsort((np.arange(len(dirs)), count, sectors))[-1])
    # fine: the plane fitted to the touching points, its own supporting plane, a few times over
    outward, rim, refitted = dirs[best], x[touch[best]], False
    for _ in range(RIM_REFINE):
        fitted = np.linalg.svd(rim - rim.mean(axis=0), full_matrices=False)[2][2]
        fitted = fitted if fitted @ outward >= 0 else -fitted
        if fitted @ dirs[best] < np.cos(np.radians(RIM_FIT_DEG)):
            break
        outward, rim, refitted = fitted, _touching(x, fitted, band), True
    if not refitted:                     # the coarse rim was taken within twice the band
        rim = _touching(x, outward, band)
    if len(rim) < RIM_MIN_TOUCHING or \
            _sectors(rim - point, outward[None], np.ones((1, len(rim)), bool))[0] < min_share * RIM_SECTORS:
        return None
    centre = rim.mean(axis=0)
    # where the line reaches the cut, its own plane is as good (and exact on the GT heatmap); where it
    # runs on past the cut (its ends follow the lumen, which the network may continue), the cut holds
    return (centre, -outward) if abs((centre - point) @ outward) > RIM_BEYOND else (point, normal)


def pushed_out(point: np.ndarray, normal: np.ndarray, points: np.ndarray,
               min_beyond: int = RIM_MIN_TOUCHING) -> tuple[np.ndarray, np.ndarray]:
    """An end's plane moved out along its normal to the cloud's extent, where the cloud runs on past it.

    Every observed point belongs to the segment, so no plane that bounds it
    may cut observed surface off. Where an end shows no cut rim, its plane
    is the centerline's (:func:`end_planes`), and on colons unlike the
    training data the network's ridge often stops well inside the segment
    (on the real training colons the planes cut away more than 5 % of the
    observed points in a quarter of the segments; docs/method.md, step 5).
    The plane keeps its normal and goes through the :data:`RIM_OUTLIERS`-th
    farthest (0-based) of the points beyond it, as the rim search's
    supporting planes do (so that a few outliers do not hold it), when at
    least ``min_beyond`` points lie beyond it; otherwise it stays.

    Parameters
    ----------
    point, normal : (3,) float
        The plane: a point on it and its inward unit normal, voxels.
    points : (n, 3) float
        The cloud's points at that end, voxels.

    Returns
    -------
    (point, inward unit normal)
    """
    beyond = (np.asarray(point, float) - np.asarray(points, float)) @ normal
    beyond = beyond[beyond > 0]
    if len(beyond) < max(min_beyond, RIM_OUTLIERS + 1):
        return point, normal
    return point - _kth_largest(beyond[None], RIM_OUTLIERS)[0] * normal, normal


def _kth_largest(values: np.ndarray, k: int) -> np.ndarray:
    """(d,) the ``k``-th largest (0-based) of each row of ``values`` (d, n); exactly ``np.partition``'s.

    The rows' ``k``-th largest over every 16th column is a lower bound of the
    true one, so only the columns at or above it in some row can be among a
    row's ``k + 1`` largest: the partition runs on those (a fifth of a cut
    rim's end points), not on all.
    """
    sub = values[:, ::16]
    if sub.shape[1] > k:
        low = -np.partition(-sub, k, axis=1)[:, k]
        values = values[:, (values >= low[:, None]).any(axis=0)]
    return -np.partition(-values, k, axis=1)[:, k]


def _touching(points: np.ndarray, outward: np.ndarray, band: float) -> np.ndarray:
    """The points within ``band`` of the supporting plane of ``points`` whose outward normal is ``outward``."""
    p = points @ outward
    return points[p > -np.partition(-p, RIM_OUTLIERS)[RIM_OUTLIERS] - band]


def _sectors(offsets: np.ndarray, axes: np.ndarray, members: np.ndarray) -> np.ndarray:
    """(d,) int: for each of the (d, 3) unit ``axes``, how many of :data:`RIM_SECTORS` equal sectors
    around it its member ``offsets`` (rows of (k, 3) where ``members`` (d, k) is true) fall in."""
    cols = np.flatnonzero(members.any(axis=0))       # the offsets in some member set (a third or fewer)
    j, i = np.nonzero(members[:, cols])
    u, v = _bases(axes)
    o = offsets[cols].T
    angle = np.arctan2((v @ o)[j, i], (u @ o)[j, i])
    sector = np.floor((angle + np.pi) / (2 * np.pi) * RIM_SECTORS).astype(int) % RIM_SECTORS
    filled = np.zeros((len(axes), RIM_SECTORS), bool)
    filled[j, sector] = True
    return filled.sum(axis=1)


def segment_planes(centerline_vox: np.ndarray, partial_vox: np.ndarray, cut_rims: bool = True) -> list:
    """The planes a completed segment is clipped at: :func:`rim_planes`, or with ``cut_rims`` off
    :func:`end_planes` (the caller clips at planes it knows)."""
    return rim_planes(centerline_vox, partial_vox) if cut_rims else end_planes(centerline_vox)


def clip_to_segment(vertices: np.ndarray, faces: np.ndarray, centerline_vox: np.ndarray, inset: float = END_INSET,
                    planes: list | None = None):
    """Drop the faces beyond the planes perpendicular to the centerline at its ends (how segments are cut).

    Marching cubes on a heatmap runs on past the cut planes by a voxel or two;
    those strips have no partial points and would count as holes (the paper's
    "nonexistent holes at the extremities"). The planes are moved ``inset``
    voxels inwards, where the surface curls as the heatmap's shell ends.
    ``planes`` (point, inward normal) replace those planes when given
    (:func:`rim_planes`).
    """
    if len(faces) == 0:
        return vertices, faces
    keep_v = inside_planes(vertices, end_planes(centerline_vox) if planes is None else planes, inset)
    return _keep_faces(vertices, faces, keep_v[faces].all(axis=1))


def line_between(centerline_vox: np.ndarray, planes: list) -> np.ndarray:
    """The centerline's points between the segment's planes (the whole line if fewer than two are): the
    line's ends follow the lumen (:data:`~colonbench.completion.heatmap_centerline.END_LEVEL`), which the network
    may continue past a cut, so a method reports its centerline between the planes it clipped at."""
    c = np.asarray(centerline_vox, float)
    inside = c[inside_planes(c, planes)] if len(c) else c
    return inside if len(inside) >= 2 else c


def inside_planes(points: np.ndarray, planes: list, inset: float = 0.0) -> np.ndarray:
    """(n,) bool: which of the (n, 3) ``points`` lie at least ``inset`` inside every (point, inward normal) plane."""
    points = np.asarray(points, float)
    keep = np.ones(len(points), bool)
    for point, normal in planes:
        keep &= (points - point) @ normal >= inset
    return keep


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
    return (p, t, *_bases(t))


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


def complete(heatmap: np.ndarray, centerline_vox: np.ndarray, partial_vox: np.ndarray,
             distance: float | None = None, cut_rims: bool = True,
             shell_level: float | None = SHELL_LEVEL, gaps: bool = True) -> Completion:
    """Mesh, holes and coverage of a segment from its target heatmap, centerline and partial cloud (voxels).

    ``distance`` is the hole distance in voxels (default: the paper's sqrt(2)/2). ``cut_rims``: clip
    at the cloud's cut rims where they are found (:func:`rim_planes`), else at the centerline's ends.
    ``shell_level``: drop the faces where the heatmap is above it (:func:`clip_to_shell`); None keeps
    every face, as before version 4 of the steps. ``gaps``: add hole patches where the tube has no wall
    (:func:`wall_gaps`), as from version 5.
    """
    verts, faces = extract_mesh(*resigned_field(heatmap, centerline_vox))
    if shell_level is not None:
        verts, faces = clip_to_shell(verts, faces, heatmap, shell_level)
    planes = segment_planes(centerline_vox, partial_vox, cut_rims)
    verts, faces = clip_to_segment(verts, faces, centerline_vox, planes=planes)
    hole = hole_vertices(verts, partial_vox, HOLE_DISTANCE if distance is None else distance)
    if gaps and len(faces):
        gap_v, gap_f = wall_gaps(heatmap, centerline_vox, planes)
        faces = np.concatenate([faces, gap_f + len(verts)])
        verts = np.concatenate([verts, gap_v])
        hole = np.concatenate([hole, np.ones(len(gap_v), bool)])
    return Completion(verts, faces, hole, mesh_coverage(verts, faces, hole), planes)
