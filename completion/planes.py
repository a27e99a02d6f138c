"""The planes that bound a segment: its centerline's end planes, or the cut rims of its cloud where they are found,
and the completed mesh clipped between them (the steps after the network, docs/method.md steps 3 and 5)."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from colonbench.completion.surface import keep_faces
from colonbench.polyline import arc_length, resample


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


#: A rim whose plane crosses the line more than this far inside the cloud's span along the line is counted
#: doubtful (:attr:`Planes.doubtful`): on a cloud seen from one side, its edge can pass for a cut rim, and clipping
#: there drops the unseen side. Kept as found (treating it as no rim cost the real colon, decision 0145), mm.
RIM_DOUBT_MM = 7.0


class Planes(list):
    """A segment's end planes, ``(point, inward unit normal)`` each, ``rims``: how many of them were found at
    a cut rim of the cloud (:func:`rim_planes`; 0 for planes found otherwise), and ``doubtful``: how many of those
    cross the line more than :data:`RIM_DOUBT_MM` inside the cloud (:func:`cuts_into_cloud`). An end with no rim is
    one the cloud does not reach, or reaches raggedly: where the segment may go on unseen. ``fill``: each end's
    share of the :data:`RIM_SECTORS` sectors its rim's points fill, 0 where it has no rim, () where no rim was
    searched for (too few points; decision record 0175: a cloud that stops at the camera's reach can pass for a cut
    rim, but rarely all round)."""

    rims: int = 0
    doubtful: int = 0
    fill: tuple = ()


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


def bases(axes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(d, 3) each: two unit vectors that make a right-handed orthonormal frame with each (d, 3) unit axis."""
    ref = np.where(np.abs(axes[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    u = np.cross(axes, ref)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    return u, np.cross(axes, u)


def cap_directions(axis: np.ndarray, max_deg: float, n: int) -> np.ndarray:
    """(n, 3) unit vectors spread evenly (a Fibonacci spiral) over the cap within ``max_deg`` of ``axis``."""
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    (u,), (v,) = bases(a[None])
    i = np.arange(n) + 0.5
    z = 1.0 - (1.0 - np.cos(np.radians(max_deg))) * i / n
    r = np.sqrt(np.clip(1.0 - z * z, 0.0, None))
    phi = np.pi * (1.0 + np.sqrt(5.0)) * i
    return z[:, None] * a + (r * np.cos(phi))[:, None] * u + (r * np.sin(phi))[:, None] * v


def rim_planes(centerline_vox: np.ndarray, partial_vox: np.ndarray, band: float = RIM_BAND,
               cap_deg: float = RIM_CAP_DEG, min_share: float = RIM_MIN_SHARE,
               voxel_mm: float = 1.0) -> list[tuple[np.ndarray, np.ndarray]]:
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
    A rim that replaces the line's plane and crosses the line more than
    :data:`RIM_DOUBT_MM` inside the cloud (``voxel_mm``: a voxel's edge, mm; 1.0
    where the inputs are in mm) is counted in ``doubtful``, and kept.

    Returns
    -------
    Planes
        (point, inward unit normal), one per end (as :func:`end_planes`), with the number found at a cut rim.
    """
    planes = Planes(end_planes(centerline_vox))
    pts = np.asarray(partial_vox, float)
    if len(planes) != 2 or len(pts) < RIM_MIN_POINTS:
        return planes
    dense = resample(np.asarray(centerline_vox, float), 0.25)
    _, nearest = cKDTree(dense).query(pts)
    out, fill = Planes(), []
    for k, (point, normal) in enumerate(planes):
        near = nearest <= RIM_END_SHARE * len(dense) if k == 0 else nearest >= (1 - RIM_END_SHARE) * len(dense)
        x = pts[near]
        rim, sectors = _rim_plane(point, normal, x, band, cap_deg, min_share)
        out.append(pushed_out(point, normal, x) if rim is None else rim)
        out.rims += rim is not None
        fill.append(sectors / RIM_SECTORS)
        # a rim at the line's own end keeps the line's plane, ``point``: nothing to doubt
        out.doubtful += rim is not None and rim[0] is not point and \
            cuts_into_cloud(rim, k, dense, nearest) * voxel_mm > RIM_DOUBT_MM
    out.fill = tuple(fill)
    return out


def _rim_plane(point: np.ndarray, normal: np.ndarray, x: np.ndarray, band: float, cap_deg: float,
               min_share: float) -> tuple[tuple[np.ndarray, np.ndarray] | None, int]:
    """One end's plane from its cut rim (:func:`rim_planes`), or None where no rim is seen there, and how many of
    :data:`RIM_SECTORS` sectors the rim's points fill (0 where there is none).

    ``point``, ``normal``: the line's end plane (:func:`end_planes`); ``x`` (n, 3): the cloud's points at
    that end, voxels.
    """
    if len(x) < RIM_MIN_POINTS:
        return None, 0
    # coarse: the directions are ~6 degrees apart, so the touching band is twice as wide
    dirs = cap_directions(-normal, cap_deg, RIM_DIRECTIONS)
    proj = dirs @ x.T                                           # (directions, points)
    touch = proj > _kth_largest(proj, RIM_OUTLIERS)[:, None] - 2 * band
    count = touch.sum(axis=1)
    touch[count < RIM_MIN_TOUCHING] = False
    sectors = _sectors(x - point, dirs, touch)
    if not sectors.any():
        return None, 0
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
    if len(rim) < RIM_MIN_TOUCHING:
        return None, 0
    filled = int(_sectors(rim - point, outward[None], np.ones((1, len(rim)), bool))[0])
    if filled < min_share * RIM_SECTORS:
        return None, 0
    centre = rim.mean(axis=0)
    # where the line reaches the cut, its own plane is as good (and exact on the GT heatmap); where it
    # runs on past the cut (its ends follow the lumen, which the network may continue), the cut holds
    return ((centre, -outward) if abs((centre - point) @ outward) > RIM_BEYOND else (point, normal)), filled


def cuts_into_cloud(plane: tuple, end: int, dense: np.ndarray, nearest: np.ndarray) -> float:
    """How far inside the cloud's span along the line a plane at one end of it crosses the line, voxels.

    Parameters
    ----------
    plane : ((3,) float, (3,) float)
        A point on the plane and its inward unit normal, voxels.
    end : int
        0 for the line's first end, 1 for its last.
    dense : (m, 3) float
        The line, densely resampled, voxels.
    nearest : (n,) int
        Each cloud point's nearest point of ``dense``.

    Returns
    -------
    float
        The arc length from the cloud's end of span (its :data:`RIM_OUTLIERS`-th point from that end, 0-based) to the
        plane's crossing (the first point of ``dense`` inside it from that end), inwards; negative where the plane
        crosses beyond the cloud; the line's length where no point of the line is inside the plane, or the cloud has
        too few points to have a span.
    """
    s = arc_length(dense)
    inside = np.flatnonzero((dense - plane[0]) @ plane[1] >= 0)
    if len(inside) == 0 or len(nearest) <= 2 * RIM_OUTLIERS:
        return float(s[-1])
    along = np.sort(s[nearest])
    if end == 0:
        return float(s[inside[0]] - along[RIM_OUTLIERS])
    return float(along[-1 - RIM_OUTLIERS] - s[inside[-1]])


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
    u, v = bases(axes)
    o = offsets[cols].T
    angle = np.arctan2((v @ o)[j, i], (u @ o)[j, i])
    sector = np.floor((angle + np.pi) / (2 * np.pi) * RIM_SECTORS).astype(int) % RIM_SECTORS
    filled = np.zeros((len(axes), RIM_SECTORS), bool)
    filled[j, sector] = True
    return filled.sum(axis=1)


def segment_planes(centerline_vox: np.ndarray, partial_vox: np.ndarray, cut_rims: bool = True,
                   voxel_mm: float = 1.0) -> list:
    """The planes a completed segment is clipped at: :func:`rim_planes` (``voxel_mm``: a voxel's edge, mm), or with
    ``cut_rims`` off :func:`end_planes` (the caller clips at planes it knows)."""
    return rim_planes(centerline_vox, partial_vox, voxel_mm=voxel_mm) if cut_rims else end_planes(centerline_vox)


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
    return keep_faces(vertices, faces, keep_v[faces].all(axis=1))


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
