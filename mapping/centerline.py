"""The centerline of a whole colon reconstruction: a point cloud with holes and missing stretches.

A reconstruction is an open surface: holes let the inside meet the outside,
so the lumen cannot be flood-filled as for a closed mesh
(:func:`colonbench.datagen.realmesh.compute_centerline`). Instead:

1. The points are rasterised at ``voxel_mm`` and dilated by ``close_mm``
   (the wall, with gaps of a sparse cloud closed).
2. A free voxel is *enclosed* when a ray from it meets the wall in at least
   ``enclosed_share`` of 26 directions (the 26-neighbourhood's): inside a tube
   nearly all rays meet the wall, holes included; outside, between limbs or in
   a bend, at most about two thirds do. The rays are cast on the grid by
   doubling: a voxel sees the wall within ``2k`` steps when it, or the voxel
   ``k`` steps ahead, sees it within ``k``.
3. The enclosed voxels, opened (no sheets or threads), split into pieces
   (6-connected, at least ``min_piece_mm`` across): where the colon has no
   wall at all for a stretch, nothing is enclosed and the colon is
   *interrupted*. Pieces whose median depth is under half the longest one's
   are channels, not lumen (inside a wall drawn as a shell), and dropped,
   unless they are at least 100 mm long and lie apart from the wider ones
   (a narrower stretch of the colon).
4. In each piece, the minimal path between its two geodesic extremities with
   a speed that grows with the distance to the wall (fast marching, the
   recipe of :mod:`colonbench.paths`), smoothed, its last two sigmas (bent by
   the smoothing) cut; then continued straight past its ends over the points
   beyond them (the rays near an open end
   of the colon escape through it, so the enclosed lumen stops short of the end
   by about a radius). With the camera trajectory, a path that leaves out part
   of it (a shortcut through a hole where two limbs touch) is sought again
   along it (:func:`_piece_path`).
5. The pieces are chained end to nearest end into one order, and joined
   where the wall lines the gap between them (a hole on one side of the
   colon, large enough to let the rays out, is no interruption): the colon
   is interrupted only where no wall lines the gap.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage

from colonbench import paths
from colonbench.completion.centerline import arc_length, resample
from colonbench.errors import InputError

#: Raster of the wall, mm.
VOXEL_MM = 2.0
#: Gaps in the wall closed by dilation, mm (a cloud of 0.5 points/mm^2 leaves about 1.4 mm).
CLOSE_MM = 4.0
#: Share of the 26 ray directions that must meet the wall for a free voxel to be inside.
ENCLOSED_SHARE = 0.8
#: Pieces of the enclosed lumen shorter than this are dropped (specks in folds), mm.
MIN_PIECE_MM = 20.0
#: Gaussian smoothing of the voxel path, mm.
SMOOTH_MM = 6.0
#: With a camera trajectory (:func:`_piece_path`): the fall-off of the path's speed away from it, mm ...
GUIDE_SIGMA_MM = 10.0
#: ... the speed factor far from it ...
GUIDE_FLOOR = 0.01
#: ... the path's extremities lie within this of it, mm ...
GUIDE_NEAR_MM = 15.0
#: ... and the trajectory guides the path where the lumen's own path leaves out this much of it, mm.
GUIDE_MISSED_MM = 20.0
#: The trajectory is taken to pass a piece's end when it comes within this many of the piece's radii
#: plus 5 mm (:func:`trajectory_reach`).
TRAJECTORY_REACH = 1.5
#: Cells on which the scope's path is loop-erased, mm (:func:`loop_erased`).
LOOP_MM = 5.0
#: A gap between two pieces is bridged straight only where the scope's path between their ends is
#: at most this many times the gap plus :data:`AROUND_MM` (:func:`_bridge`).
AROUND_FACTOR = 2.0
AROUND_MM = 30.0
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


def _piece_paths(inside: np.ndarray, dist: np.ndarray, voxel_mm: float, guide: np.ndarray | None = None,
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


def _extend(line: np.ndarray, cloud: np.ndarray, radius: float, reach_mm: float = 10.0) -> np.ndarray:
    """``line`` continued straight past each end (its tangent over the last ``reach_mm``) over the points beyond.

    It goes as far as the cloud's points ahead of the end (those within
    ``2 * radius`` of its axis, so another limb beyond the end does not pull
    it on; their 99.5th percentile), and at most ``2 * radius``: the enclosed
    lumen stops short of an open end by about a radius (and the smoothed
    path's ends were cut by two sigmas), a closed pole (the caecum) ends the
    points anyway, and further out the straight line leaves a bending colon. (Continuing with the end's curvature was
    no better on a helical tube: the last centimetre's turning is mostly noise.)
    """
    out = np.asarray(line, float)
    for end in (0, 1):
        pts = out if end == 1 else out[::-1]
        if len(pts) < 2:
            continue
        t = pts[-1] - pts[max(len(pts) - 1 - int(reach_mm), 0)]
        if np.linalg.norm(t) < 1e-9:
            continue
        t = t / np.linalg.norm(t)
        rel = cloud - pts[-1]
        along = rel @ t
        across = np.linalg.norm(rel - along[:, None] * t, axis=1)
        ahead = along[(along > 0) & (across < 2.0 * radius)]
        if len(ahead) == 0:
            continue
        extra = int(round(min(float(np.percentile(ahead, 99.5)), 2.0 * radius)))
        if extra < 1:
            continue
        new = pts[-1] + np.arange(1.0, extra + 1.0)[:, None] * t
        out = np.concatenate([out, new]) if end == 1 else np.concatenate([new[::-1], out])
    return out


def _chain(pieces: list[Piece]) -> list[Piece]:
    """Pieces ordered end to nearest end, each oriented to continue the previous one."""
    if len(pieces) <= 1:
        return pieces
    ends = [(p.points[0], p.points[-1]) for p in pieces]

    def gap(i, j):  # shortest distance between an end of i and an end of j
        return min(np.linalg.norm(a - b) for a in ends[i] for b in ends[j])

    n = len(pieces)
    # start with the piece whose nearest neighbour is farthest: an end of the chain
    first = max(range(n), key=lambda i: min(gap(i, j) for j in range(n) if j != i))
    left = set(range(n)) - {first}
    line = pieces[first].points
    # orient the first piece so that its far end (from the rest) comes first
    rest = np.concatenate([pieces[j].points[[0, -1]] for j in left])
    if np.linalg.norm(rest - line[0], axis=1).min() < np.linalg.norm(rest - line[-1], axis=1).min():
        pieces[first] = Piece(line[::-1].copy(), pieces[first].radius)
    out = [pieces[first]]
    while left:
        tip = out[-1].points[-1]
        j = min(left, key=lambda i: min(np.linalg.norm(ends[i][0] - tip), np.linalg.norm(ends[i][1] - tip)))
        p = pieces[j].points
        if np.linalg.norm(p[-1] - tip) < np.linalg.norm(p[0] - tip):
            p = p[::-1].copy()
        out.append(Piece(p, pieces[j].radius))
        left.remove(j)
    return out


def loop_erased(path: np.ndarray, cell_mm: float = LOOP_MM) -> np.ndarray:
    """A polyline with its loops erased, on cells of ``cell_mm``: where it enters a cell it has passed
    through before, everything since is dropped (loop erasure of the walk's cells).

    A scope pushed back in and withdrawn again passes the same cells twice; the
    erased path passes them once, in the order of its last pass. Consecutive
    points in one cell keep the first.
    """
    path = np.asarray(path, float).reshape(-1, 3)
    cells = [tuple(c) for c in np.floor(path / cell_mm).astype(np.int64)]
    out, where = [], {}
    for point, cell in zip(path, cells):
        k = where.get(cell)
        if k is not None:
            for dropped in out[k + 1:]:
                del where[dropped[1]]
            del out[k + 1:]
            continue
        where[cell] = len(out)
        out.append((point, cell))
    return np.array([q for q, _ in out]).reshape(-1, 3)


def trajectory_reach(radius: float, reach: float = TRAJECTORY_REACH) -> float:
    """How near a piece's end of ``radius`` (mm) the trajectory must come to pass it, mm."""
    return reach * radius + 5.0


def _trajectory_between(positions: np.ndarray, a: np.ndarray, b: np.ndarray, near: float,
                        places: tuple | None = None) -> np.ndarray | None:
    """The scope's path from near ``a`` to near ``b`` (loop-erased, ends ``a`` and ``b``), or None where the
    trajectory does not come within ``near`` of both.

    ``places`` ((3,), (3,) mm, optional): where on its path the scope passed ``a`` and ``b``
    (:meth:`ScopeRoute.end_place`); only poses within ``near`` of those are taken, so that an end lying
    nearer to a touching limb's stretch of the trajectory than to its own is passed where it belongs.
    """
    da, db = np.linalg.norm(positions - a, axis=1), np.linalg.norm(positions - b, axis=1)
    if places is not None:
        da[np.linalg.norm(positions - places[0], axis=1) > near] = np.inf
        db[np.linalg.norm(positions - places[1], axis=1) > near] = np.inf
    ta, tb = int(np.argmin(da)), int(np.argmin(db))
    if da[ta] > near or db[tb] > near or ta == tb:
        return None
    window = positions[min(ta, tb): max(ta, tb) + 1]
    window = window if ta < tb else window[::-1]
    return np.concatenate([[a], loop_erased(window), [b]])


class ScopeRoute:
    """The scope's path through the colon: its trajectory loop-erased (:func:`loop_erased`), at 1 mm.

    A withdrawal passes each place of the colon in turn, so the arc length along this path orders
    the colon's stretches by when the scope passed them, and a point's nearest place on it says
    which stretch the point belongs to.

    Parameters
    ----------
    positions : (k, 3) float
        Camera positions in time order, mm.
    """

    def __init__(self, positions: np.ndarray):
        from scipy.spatial import cKDTree

        erased = loop_erased(np.asarray(positions, float))
        self.points = resample(erased, 1.0) if len(erased) > 1 else erased
        self.arc = arc_length(self.points)
        self._tree = cKDTree(self.points)

    def along(self, points: np.ndarray, reach: float = np.inf) -> np.ndarray:
        """(n,) arc length along the path (mm) of each point's nearest place on it; NaN beyond ``reach`` mm."""
        d, k = self._tree.query(np.asarray(points, float))
        return np.where(d <= reach, self.arc[k], np.nan)

    def end_place(self, line: np.ndarray, reach: float, last: bool, window_mm: float = 20.0) -> float | None:
        """Where the scope passed one end of ``line``: arc length on the path, mm, or None where none of the
        end's points lies within ``reach`` (mm) of the path.

        Each point within ``window_mm`` of that end and within ``reach`` of the path gives its own place,
        carried on to the end along ``line`` (the way the places run there); their median is the end's.
        A single end point can lie nearer to a touching limb's stretch of the path than to its own.
        """
        line = np.asarray(line, float)
        s = arc_length(line)
        end = s[-1] if last else 0.0
        near = np.abs(s - end) <= window_mm
        u = self.along(line[near], reach)
        ok = np.isfinite(u)
        if not ok.any():
            return None
        u, s = u[ok], s[near][ok]
        return float(np.clip(np.median(u + self.way(u) * (end - s)), 0.0, self.arc[-1]))

    @staticmethod
    def way(places: np.ndarray) -> float:
        """Which way the scope's places run along a line's points in order: +1 when it passed the line's second
        half later than its first (the median of each), -1 when earlier, 0 for fewer than two places."""
        half = len(places) // 2
        return float(np.sign(np.median(places[half:]) - np.median(places[:half]))) if half else 0.0

    def left_out(self, line: np.ndarray, start: float, stop: float, reach: float) -> float:
        """How much of the path between arc lengths ``start`` and ``stop`` lies farther than ``reach`` from
        ``line`` ((m, 3)), mm."""
        from scipy.spatial import cKDTree

        part = self.points[(self.arc > min(start, stop)) & (self.arc < max(start, stop))]
        if len(part) == 0:
            return 0.0
        return float(np.sum(cKDTree(line).query(part)[0] > reach))  # the path is sampled every mm

    def at(self, place: float) -> np.ndarray:
        """(3,) the path's point at arc length ``place``, mm."""
        return self.points[int(np.clip(np.searchsorted(self.arc, place), 0, len(self.points) - 1))]


def split_at_shortcuts(pieces: list[Piece], positions: np.ndarray | None,
                       min_mm: float = MIN_PIECE_MM) -> list[Piece]:
    """The pieces cut where they leave the colon the scope went through, each place of the colon kept once.

    Along a piece that follows the colon, the scope's path (loop-erased, :func:`loop_erased`) passes each
    point in turn: the arc length along that path of each point's nearest trajectory point grows as the
    piece's does. Where two limbs of the colon touch and a hole opens both walls, and the colon around is
    not enclosed (collapsed, or not reconstructed), the lumen's path crosses through the hole, and that arc
    length jumps by the colon left out: by more than :data:`AROUND_FACTOR` times the step plus
    :data:`AROUND_MM`, with at least :data:`GUIDE_MISSED_MM` of the scope's path in between farther from
    the piece than the trajectory's reach (:func:`trajectory_reach`; a loop the erasure left, where the
    scope was pushed back in a few mm off its first way, stays by the piece). The piece is cut there, and
    its line out of the trajectory's reach at the cut (through the hole) is dropped; the parts that run
    over a stretch a longer part already holds (the line back along the other limb) are trimmed to what
    no longer part holds, and parts left under ``min_mm`` are dropped.
    :func:`colonbench.mapping.colonmap.orient` then orders the parts by the trajectory and
    :func:`bridge_by_trajectory` joins them along it: the stretch left out is mapped.

    Parameters
    ----------
    pieces : list of Piece
        The centerline's pieces (:func:`colon_centerline`).
    positions : (k, 3) float or None
        Camera positions in time order, mm; without them the pieces are returned as they are.
    min_mm : float
        Shortest part kept, mm.

    Returns
    -------
    list of Piece
        The parts, in no particular order (the orientation orders them); the pieces themselves where
        nothing jumps.
    """
    if positions is None or len(positions) < 2:
        return pieces
    route = ScopeRoute(positions)
    parts = []  # (piece, u of each point: NaN where the trajectory is out of reach, or None: kept whole)
    cut = False
    for p in pieces:
        if p.unseen or len(p.points) < 2:  # already joined along the trajectory
            parts.append((p, None))
            continue
        u = route.along(p.points, trajectory_reach(p.radius))
        s = arc_length(p.points)
        known = np.flatnonzero(np.isfinite(u))
        jumps = np.flatnonzero(np.abs(np.diff(u[known])) > AROUND_FACTOR * np.diff(s[known]) + AROUND_MM)
        # a loop of the scope's path that the erasure left (pushed back in off its first way) stays by the
        # piece; the colon a shortcut leaves out lies away from it
        jumps = [j for j in jumps if route.left_out(p.points, u[known[j]], u[known[j + 1]],
                                                    trajectory_reach(p.radius)) >= GUIDE_MISSED_MM]
        cut = cut or bool(jumps)
        cuts = [0] + [int(known[j + 1]) for j in jumps] + [len(p.points)]
        for a, b in zip(cuts[:-1], cuts[1:]):
            # a part starts at a point within the trajectory's reach; before a cut, the line out of its
            # reach (through the hole) is no part
            if b < len(p.points):
                b = int(known[np.searchsorted(known, b) - 1]) + 1
            if b - a >= 2:
                parts.append((Piece(p.points[a:b], p.radius), u[a:b]))
    if not cut:
        return pieces
    # the longest parts keep their stretch of the scope's path; the others only what none of those holds
    held = np.zeros((0, 2))  # (lowest, highest) place of each part kept
    out = []
    for part, u in sorted(parts, key=lambda x: -len(x[0].points)):
        if u is None or not np.isfinite(u).any():
            out.append(part)
            continue
        free = ~np.any((u[:, None] >= held[:, 0]) & (u[:, None] <= held[:, 1]), axis=1)  # NaN: free
        label, n = ndimage.label(free)
        if n == 0:
            continue
        runs = ndimage.find_objects(label)
        (run,) = max(runs, key=lambda r: r[0].stop - r[0].start)
        keep, uk = Piece(part.points[run], part.radius), u[run]
        if len(keep.points) < 2 or keep.length < min_mm:
            continue
        out.append(keep)
        if np.isfinite(uk).any():
            held = np.vstack([held, [np.nanmin(uk), np.nanmax(uk)]])
    return out


def _bridge(pieces: list[Piece], cloud: np.ndarray, covered: float = 0.9,
            positions: np.ndarray | None = None) -> list[Piece]:
    """Consecutive pieces joined across gaps that the wall still lines (a large hole, not a missing stretch).

    A gap is bridged by the straight line between the two ends when at least
    ``covered`` of its 1 mm steps have a point of the cloud within 1.2 radii:
    one side of the colon unseen for a few centimetres opens the lumen to the
    rays but leaves the other side's wall along the gap. Where the colon is
    missing, no wall lines the gap and the pieces stay apart. With the camera
    ``positions``, a gap the scope went around (its path between the two
    ends longer than :data:`AROUND_FACTOR` times the gap plus
    :data:`AROUND_MM`) is not bridged straight: the ends face each other
    across two limbs, whose walls line the straight line, and the colon runs
    the long way (:func:`bridge_by_trajectory` joins them along the scope).
    """
    from scipy.spatial import cKDTree

    if len(pieces) < 2:
        return pieces
    tree = cKDTree(cloud)
    pos = None if positions is None or len(positions) < 2 else np.asarray(positions, float)
    out = [pieces[0]]
    for p in pieces[1:]:
        a, b = out[-1].points[-1], p.points[0]
        gap = float(np.linalg.norm(b - a))
        radius = max(out[-1].radius, p.radius)
        if pos is not None:
            scope = _trajectory_between(pos, a, b, trajectory_reach(radius))
            if scope is not None and np.linalg.norm(np.diff(scope, axis=0), axis=1).sum() > (
                    AROUND_FACTOR * gap + AROUND_MM):
                out.append(p)
                continue
        steps = np.linspace(0.0, 1.0, max(int(gap), 1) + 1)[1:-1]
        if len(steps):
            probe = a + steps[:, None] * (b - a)
            d, _ = tree.query(probe, distance_upper_bound=1.2 * radius)
            lined = float(np.mean(np.isfinite(d)))
        else:
            lined = 1.0
        if lined >= covered:
            joined = np.concatenate([out[-1].points, a + steps[:, None] * (b - a), p.points])
            out[-1] = Piece(resample(joined, 1.0), float(np.mean([out[-1].radius, p.radius])))
        else:
            out.append(p)
    return out


def _drop_channels(pieces: list[tuple[Piece, float]], long_mm: float = 100.0, apart: float = 1.5) -> list[Piece]:
    """The pieces that are stretches of the colon's lumen, not channels beside it.

    A piece far narrower than the longest one (under half its median depth)
    is a channel (the gap inside a wall drawn as a shell, a pocket between
    folds) unless it is at least ``long_mm`` long and lies apart from the
    wider pieces (at least ``apart`` of their radius from their centerlines
    over 80 % of its length): then it is a narrower stretch of the colon (a
    narrow limb of a real colon, a noisy reconstruction's thin lumen).
    """
    from scipy.spatial import cKDTree

    longest = max(pieces, key=lambda p: p[0].length)[1]
    wide = [p for p, depth in pieces if depth >= 0.5 * longest]
    tree = cKDTree(np.concatenate([p.points for p in wide]))
    radius = max(p.radius for p in wide)
    kept = []
    for p, depth in pieces:
        if depth >= 0.5 * longest:
            kept.append(p)
        elif p.length >= long_mm:
            d, _ = tree.query(p.points)
            if np.mean(d > apart * radius) >= 0.8:
                kept.append(p)
    return kept


def colon_centerline(points, voxel_mm: float = VOXEL_MM, close_mm: float = CLOSE_MM,
                     enclosed_share: float = ENCLOSED_SHARE, min_piece_mm: float = MIN_PIECE_MM,
                     smooth_mm: float = SMOOTH_MM, positions: np.ndarray | None = None) -> list[Piece]:
    """The centerline of a colon reconstruction, in uninterrupted pieces, chained in order.

    Parameters
    ----------
    points : (n, 3) float
        The reconstruction's points, mm.
    voxel_mm, close_mm, enclosed_share, min_piece_mm, smooth_mm : float
        See the module's description.
    positions : (k, 3) float, optional
        Camera positions in time order, mm, the points' frame. Each piece's path then keeps to
        the lumen the scope went through (:func:`_piece_path`); without them it is the lumen's
        longest path, which can cut through a hole where two limbs of the colon touch.

    Returns
    -------
    list of Piece
        Ordered along the colon (the direction is arbitrary: the first piece's
        first point is one end of the chain); more than one where the colon is
        interrupted.

    Raises
    ------
    InputError
        When nothing is enclosed: not a tube, or far too sparse.
    """
    import edt

    pts = np.asarray(points, float)
    close = max(int(round(close_mm / voxel_mm)), 0)
    occupied, origin = rasterise(pts, voxel_mm, pad=close + 2)
    wall = ndimage.binary_dilation(occupied, iterations=close) if close else occupied
    hits = ray_hits(wall)
    inside = ~wall & (hits >= int(np.ceil(enclosed_share * len(DIRECTIONS))))
    # thin sheets and threads between dilated walls are no lumen (and fast marching needs faces)
    inside = ndimage.binary_opening(inside)
    # the wall was dilated by `close`: the lumen's distance to the true wall is `close` voxels more
    dist = edt.edt(inside, anisotropy=(voxel_mm,) * 3)
    guide = None
    if positions is not None and len(positions):
        guide = trajectory_distance(positions, origin, inside.shape, voxel_mm)
    label, n = ndimage.label(inside)
    if n == 0:
        raise InputError("no lumen found: the points do not enclose a tube (is this a colon reconstruction "
                         "in mm?)")
    pieces = []
    extents = ndimage.find_objects(label)
    for lab, box in enumerate(extents, start=1):
        span = np.linalg.norm([(s.stop - s.start) * voxel_mm for s in box])
        if span < min_piece_mm:
            continue
        # one empty voxel around the piece (the grid's padding holds it): fast marching needs a border
        box = tuple(slice(s.start - 1, s.stop + 1) for s in box)
        part = label[box] == lab
        for vox in _piece_paths(part, dist[box], voxel_mm, None if guide is None else guide[box], min_piece_mm):
            # geodesic extremities lie at the rim of the enclosed lumen, off its axis: keep the path from where
            # it is at least 0.7 of its median depth (as for closed meshes, datagen.realmesh.compute_centerline)
            depth = dist[box][tuple(vox.T)]
            deep = np.flatnonzero(depth >= 0.7 * np.median(depth))
            vox, depth = vox[deep[0]: deep[-1] + 1], depth[deep[0]: deep[-1] + 1]
            if len(vox) < 4:
                continue
            line = origin + (paths.smooth_path(vox, smooth_mm / voxel_mm) + [s.start for s in box]) * voxel_mm
            line = resample(line, 1.0)
            # smoothing bends the last sigma or two of a path's ends: they are grown again from the points
            trim = int(round(2 * smooth_mm))
            if len(line) < 2 * trim + 4:
                continue
            line = line[trim: len(line) - trim]
            depth = float(np.median(depth))
            pieces.append((Piece(line, depth + close * voxel_mm), depth))
    if pieces:
        pieces = _drop_channels(pieces)
    if not pieces:
        raise InputError("no stretch of lumen longer than "
                         f"{min_piece_mm:g} mm found: the points do not enclose a tube")
    # the pieces' ends, extended over the points beyond them (open ends lose about a radius);
    # each piece's points: those nearest to it
    from scipy.spatial import cKDTree

    owner = np.concatenate([np.full(len(p.points), i) for i, p in enumerate(pieces)])
    _, near = cKDTree(np.concatenate([p.points for p in pieces])).query(pts)
    for i, p in enumerate(pieces):
        mine = pts[owner[near] == i]
        if len(mine):
            pieces[i] = Piece(resample(_extend(p.points, mine, p.radius), 1.0), p.radius)
    return _bridge(_chain(pieces), pts, positions=positions)


def bridge_by_trajectory(pieces: list[Piece], positions: np.ndarray | None, cloud: np.ndarray | None = None,
                         reach: float = TRAJECTORY_REACH, max_detour: float = 10.0, smooth_mm: float = 5.0,
                         min_unseen_mm: float = 5.0) -> list[Piece]:
    """Consecutive pieces joined along the camera trajectory where it passes from one to the next.

    Where the colon has no reconstruction over a stretch (a tracking loss, a
    stretch the pipeline could not fuse) the pieces stay apart
    (:func:`colon_centerline`). If the colonoscope went from the end of one
    piece to the start of the next, the colon is continuous there: the pieces
    are joined by the trajectory's path between them (loop-erased,
    :func:`loop_erased`, so that pushing the scope back in does not fold the
    line; smoothed by ``smooth_mm``; each end's pose sought near where the scope
    passed it, :meth:`ScopeRoute.end_place`, from the piece's last 20 mm),
    however far around it goes: where two
    limbs touch, the next piece's end can lie a few centimetres away across
    them while the colon between runs for decimetres. Where the path's 2 mm thick
    cross-sections hold no point of the cloud within 1.5 radii for at least
    ``min_unseen_mm`` (no wall on any side), the stretch is recorded in the joined piece's ``unseen`` as
    not reconstructed; where the wall lines the path (a narrow or collapsed
    stretch the lumen search lost), it is only joined.

    Parameters
    ----------
    pieces : list of Piece
        Chained and oriented (:func:`colon_centerline`, then the map's orientation).
    positions : (k, 3) float or None
        Camera positions in time order, mm, the reconstruction's frame.
    cloud : (n, 3) float, optional
        The reconstruction's points, mm (without them every joined stretch counts as unseen).
    reach : float
        The trajectory must come within ``reach`` radii (plus 5 mm) of both piece ends' last 20 mm.
    max_detour : float
        A path longer than ``max_detour`` times the straight gap plus 50 mm is not used (the two ends
        are then not consecutive along the colon).
    smooth_mm : float
        Gaussian smoothing of the path, mm.

    Returns
    -------
    list of Piece
        Joined where the trajectory bridges a gap; the others as they were.
    """
    if positions is None or len(pieces) < 2 or len(positions) < 2:
        return pieces
    from scipy.spatial import cKDTree

    pos = np.asarray(positions, float)
    route = ScopeRoute(pos)
    cloud = None if cloud is None else np.asarray(cloud, float)
    tree = cKDTree(cloud) if cloud is not None and len(cloud) else None
    out = [Piece(pieces[0].points, pieces[0].radius, list(pieces[0].unseen))]
    for p in pieces[1:]:
        prev = out[-1]
        a, b = prev.points[-1], p.points[0]
        near = trajectory_reach(max(prev.radius, p.radius), reach)
        ua, ub = route.end_place(prev.points, near, last=True), route.end_place(p.points, near, last=False)
        path = None
        if ua is not None and ub is not None:
            path = _trajectory_between(pos, a, b, near, places=(route.at(ua), route.at(ub)))
        if path is not None:
            path = resample(path, 1.0)
            if len(path) > 4:
                inner = ndimage.gaussian_filter1d(path, smooth_mm, axis=0, mode="nearest")
                inner[0], inner[-1] = a, b
                path = resample(inner, 1.0)
            gap = float(np.linalg.norm(b - a))
            if np.linalg.norm(np.diff(path, axis=0), axis=1).sum() > max_detour * gap + 50.0:
                path = None
        if path is None:
            out.append(Piece(p.points, p.radius, list(p.unseen)))
            continue
        s0 = prev.length
        arc = arc_length(path)
        bridge = float(arc[-1])
        radius = max(prev.radius, p.radius)
        empty = np.ones(len(path), bool)
        if tree is not None:  # the wall lines a step: a point within 1.5 radii, in its 2 mm thick cross-section
            tangent = np.gradient(path, axis=0)
            tangent /= np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), 1e-9)
            for k, near_ids in enumerate(tree.query_ball_point(path, 1.5 * radius)):
                if near_ids:
                    empty[k] = not np.any(np.abs((cloud[near_ids] - path[k]) @ tangent[k]) < 1.0)
        label, _ = ndimage.label(empty)  # the runs of the path with no wall
        runs = [(s0 + arc[r.start], s0 + arc[r.stop - 1]) for (r,) in ndimage.find_objects(label)
                if arc[r.stop - 1] - arc[r.start] >= min_unseen_mm]
        joined = np.concatenate([prev.points, path[1:-1], p.points])
        steps = np.linalg.norm(np.diff(joined, axis=0), axis=1)
        keep = np.concatenate([[True], steps > 1e-6])
        out[-1] = Piece(joined[keep], float(np.mean([prev.radius, p.radius])),
                        prev.unseen + runs + [(s0 + bridge + u0, s0 + bridge + u1) for u0, u1 in p.unseen])
    return out
