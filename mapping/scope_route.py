"""The scope's trajectory as a route through the colon: loop-erased, it places every point along the colon the scope
went through, cuts a centerline where it shortcuts that route, and bridges the pieces of a centerline along it.

Step 5 of :mod:`colonbench.mapping.reconstruction_centerline` and the map's bridges."""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from colonbench.mapping.lumen_paths import GUIDE_MISSED_MM, MIN_PIECE_MM, Piece
from colonbench.polyline import arc_length, resample


#: The trajectory is taken to pass a piece's end when it comes within this many of the piece's radii
#: plus 5 mm (:func:`trajectory_reach`).
TRAJECTORY_REACH = 1.5


#: Cells on which the scope's path is loop-erased, mm (:func:`loop_erased`).
LOOP_MM = 5.0


#: A gap between two pieces is bridged straight only where the scope's path between their ends is
#: at most this many times the gap plus :data:`AROUND_MM` (:func:`bridge_pieces`).
AROUND_FACTOR = 2.0


AROUND_MM = 30.0


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


def bridge_pieces(pieces: list[Piece], cloud: np.ndarray, covered: float = 0.9,
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
