"""``colonbench map``: one colon reconstruction in, a per-segment coverage map out.

Steps: the reconstruction's centerline in uninterrupted pieces
(:mod:`colonbench.mapping.reconstruction_centerline`); oriented from the rectum when a
trajectory says where the withdrawal ended; pieces joined along the
trajectory where the scope passed a stretch with no reconstruction (that
stretch counted unobserved); cut into segments of a given arc
length by planes perpendicular to it; every point given to the segment of its
nearest centerline point (the segment-only protocol's cut, by the nearest
stretch so that a bend does not hand a neighbour's wall over); each segment
estimated by a method on its own points alone; results written.
"""

from __future__ import annotations

import copy
import time
from dataclasses import dataclass, replace

import numpy as np

from colonbench.errors import InputError
from colonbench.mapping import SEGMENT_MM
from colonbench.mapping.map_review import review_by_point_rate
from colonbench.mapping.reach import beyond_reach, unreached_error
from colonbench.mapping.segments import (MIN_HOLE_MM2, Segment, add_unreconstructed, few_points_error,
                                         hole_regions)
from colonbench.slab import point_at

#: A segment with fewer points is reported without an estimate.
MIN_POINTS = 200


def _frame(line: np.ndarray, s: np.ndarray, at: float, half_mm: float = 8.0) -> dict:
    """Plane through the centerline at arc length ``at``, normal along its chord over ``at +- half_mm``."""
    lo = int(np.clip(np.searchsorted(s, at - half_mm), 0, len(s) - 1))
    hi = int(np.clip(np.searchsorted(s, at + half_mm), 0, len(s) - 1))
    t = line[hi] - line[lo]
    t = t / max(np.linalg.norm(t), 1e-12)
    p = point_at(line, s, at)
    return {"point": np.round(p, 3).tolist(), "normal": np.round(t, 6).tolist()}


def windows(length: float, segment_mm: float) -> list[tuple[float, float]]:
    """Windows of ``segment_mm`` over ``[0, length]``; a remainder under half a segment joins the last one."""
    n = int(length // segment_mm)
    rest = length - n * segment_mm
    if n == 0:
        return [(0.0, length)]
    bounds = [(k * segment_mm, (k + 1) * segment_mm) for k in range(n)]
    if rest >= 0.5 * segment_mm:
        bounds.append((n * segment_mm, length))
    else:
        bounds[-1] = (bounds[-1][0], length)
    return bounds


def orient(pieces: list, positions: np.ndarray | None) -> tuple[list, str]:
    """The pieces ordered and turned so that the map starts at the rectum, when the trajectory says where.

    A withdrawal ends at the rectum. With a trajectory each piece is turned
    so that the camera passed its first half later than its second, and
    the pieces are ordered by when the camera passed them, latest first: the
    trajectory, not the pieces' nearness, says which stretch follows which
    (limbs of a colon can touch). "When" is the arc length along the scope's
    loop-erased path (:class:`colonbench.mapping.scope_route.ScopeRoute`) of
    each point's nearest place on it, the median over the piece, and over its
    points within reach of the path where it has any: where limbs touch, a
    piece's end can lie nearer to the other limb's stretch of the path than to its own.
    Without a trajectory the chain is kept as found.
    """
    from colonbench.mapping.lumen_paths import Piece
    from colonbench.mapping.scope_route import ScopeRoute, trajectory_reach

    if positions is None:
        return pieces, "unknown (no trajectory): numbered from one end of the centerline"

    def turn(p):
        return Piece(p.points[::-1].copy(), p.radius, list(p.unseen))

    if len(pieces) == 1:  # one piece: the end nearer to the last camera position is the rectum's
        (p,) = pieces
        tip = positions[-1]
        if np.linalg.norm(p.points[-1] - tip) < np.linalg.norm(p.points[0] - tip):
            p = turn(p)
        return [p], "from the rectum (the end of the trajectory)"
    route = ScopeRoute(positions)
    turned = []
    for p in pieces:
        # where the scope passed each point (its own stretch's, not a touching limb's, where it can tell)
        u = route.along(p.points, trajectory_reach(p.radius))
        u = u[np.isfinite(u)] if np.isfinite(u).sum() >= 2 else route.along(p.points)
        if ScopeRoute.way(u) > 0:  # passed later at its end: the rectum's
            p = turn(p)
        turned.append((float(np.median(u)), p))
    turned.sort(key=lambda x: -x[0])
    return [p for _, p in turned], "from the rectum (the end of the trajectory; pieces ordered by it)"


def clip_between(vertices: np.ndarray, faces: np.ndarray, line: np.ndarray, arc: np.ndarray, lo: float,
                 hi: float) -> np.ndarray:
    """Faces of a mesh whose centroid's nearest point of the centerline ``line`` lies at arc length in [lo, hi)."""
    from scipy.spatial import cKDTree

    if len(faces) == 0:
        return faces
    _, near = cKDTree(line).query(vertices[faces].mean(axis=1))
    s = arc[near]
    return faces[(s >= lo) & (s < hi)]


def for_mapping(method, context_mm: float = 0.0):
    """The method as mapping runs it: a method that can clip at its cloud's cut rims (``cut_rims``) does not,
    and on a segment alone (``context_mm`` 0) its centerline keeps the ends of its ridge (``end_level``).

    The map splits the reconstruction by the arc length of each point's nearest centerline point, not
    by planes, so a segment's cloud does not end in a planar rim, and the map clips the completed
    surface at its own planes. On the whole-colon benchmark the rims, searched for anyway, cost the
    real colon's segments 1.8-3.0 points (docs/decisions/0202-map-does-not-search-for-cut-rims.md). Without rims nothing holds a centerline
    that follows the lumen's core past the segment's ends (docs/method.md step 3), and on a segment
    alone the mesh is not clipped to the segment's stretch either: there the line's ends on the core
    cost the segment-only track 3 points (docs/decisions/0204-method-steps-4-5-6-on-the-map-tracks.md), while in context, clipped to the stretch,
    they gained. An in-context model (``needs_slab``) is always clipped to its segment's stretch, so it keeps its
    ends on the core. A calibration with a review threshold of the map's own (completion's ``intervals``, decision
    record 0223) reviews the segments by it. Such a method comes back as a shallow copy (sharing its loaded model);
    the caller's object is left as it is.
    """
    changes = {}
    if getattr(method, "cut_rims", False):
        changes["cut_rims"] = False
    if context_mm <= 0 and not getattr(method, "needs_slab", False) and getattr(method, "end_level", None) is not None:
        changes["end_level"] = None
    cal = getattr(method, "intervals", None)
    mapped_cal = cal.for_map() if callable(getattr(cal, "for_map", None)) else cal   # the map's own review (0223)
    if mapped_cal is not cal:
        changes["intervals"] = mapped_cal
    if not changes:
        return method
    mapped = copy.copy(method)
    for name, value in changes.items():
        setattr(mapped, name, value)
    return mapped


def map_centerline(points: np.ndarray, positions: np.ndarray | None = None, pieces: list | None = None):
    """The map's centerline of a reconstruction: its pieces found, oriented and joined along the trajectory.

    Parameters
    ----------
    points : (n, 3) float
        The reconstruction, mm.
    positions : (k, 3) float, optional
        Camera positions in time order, mm, same frame.
    pieces : list of colonbench.mapping.lumen_paths.Piece, optional
        ``colon_centerline(points, positions=positions)`` when the caller has it already.

    Returns
    -------
    pieces : list of colonbench.mapping.lumen_paths.Piece
        In map order (:func:`orient`), bridged where the trajectory passes between them.
    orientation : str
    """
    from colonbench.mapping.reconstruction_centerline import colon_centerline
    from colonbench.mapping.scope_route import bridge_by_trajectory, split_at_shortcuts

    pieces = colon_centerline(points, positions=positions) if pieces is None else pieces
    pieces, orientation = orient(split_at_shortcuts(pieces, positions), positions)
    return bridge_by_trajectory(pieces, positions, points), orientation


def single_segment(length_mm: float, segment_mm: float) -> str:
    """Why the map takes a centerline of ``length_mm`` for a single segment and maps nothing: it is shorter than
    two segments of ``segment_mm``; "" where the map takes it for a colon."""
    if length_mm < 2 * segment_mm:
        return (f"the centerline found is {length_mm:.0f} mm long, not more than two segments of {segment_mm:g} mm: "
                "this looks like a single segment, not a colon")
    return ""


@dataclass
class JoinedLine:
    """The map's pieces as one centerline, arc length running on over the gaps between them (mm).

    Attributes
    ----------
    lines, arcs : list of (m_k,) arrays
        Each piece's points ((m_k, 3)) and arc lengths ((m_k,)) on the joined line.
    line : (m, 3) float
    arc : (m,) float
        All pieces' points and arc lengths, in order.
    owner : (m,) int
        The piece of each point of ``line``.
    spans : list of (float, float)
        Each piece's first and last arc length.
    interruptions : list of dict
        ``after_mm``, ``gap_mm``, ``point_before``, ``point_after`` of each gap between pieces.
    unseen : list of (float, float)
        Stretches a trajectory bridges with no reconstruction, arc lengths.
    """

    lines: list
    arcs: list
    line: np.ndarray
    arc: np.ndarray
    owner: np.ndarray
    spans: list
    interruptions: list
    unseen: list

    def assign(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Arc length ((n,) mm) and piece ((n,) int) of each point's nearest centerline point."""
        from scipy.spatial import cKDTree

        _, nearest = cKDTree(self.line).query(points)
        return self.arc[nearest], self.owner[nearest]


def join_pieces(pieces: list) -> JoinedLine:
    """The :class:`JoinedLine` of the map's pieces (:func:`map_centerline`), in their order."""
    lines, arcs, owner, interruptions, spans, unseen = [], [], [], [], [], []
    s0 = 0.0
    for k, p in enumerate(pieces):
        if k:
            gap = float(np.linalg.norm(p.points[0] - lines[-1][-1]))
            interruptions.append({"after_mm": round(s0, 2), "gap_mm": round(gap, 2),
                                  "point_before": np.round(lines[-1][-1], 3).tolist(),
                                  "point_after": np.round(p.points[0], 3).tolist()})
            s0 += gap
        seg = np.linalg.norm(np.diff(p.points, axis=0), axis=1)
        s = s0 + np.concatenate([[0.0], np.cumsum(seg)])
        lines.append(p.points)
        arcs.append(s)
        owner.append(np.full(len(s), k))
        spans.append((s[0], s[-1]))
        unseen += [(s[0] + u0, s[0] + u1) for u0, u1 in p.unseen]
        s0 = s[-1]
    return JoinedLine(lines, arcs, np.concatenate(lines), np.concatenate(arcs), np.concatenate(owner), spans,
                      interruptions, unseen)


def mapped_interval(method, est, coverage: float) -> tuple[list[float], list[str]]:
    """The method's interval around the map's coverage of a segment, and its review decided on that interval: the map's
    coverage differs from the estimate's where the map clips the completed surface to the segment's stretch or counts
    a stretch no point reached.

    Parameters
    ----------
    method : object
        The method as the map runs it; a method with a calibration (completion's ``intervals``, an
        :class:`~colonbench.completion.intervals.Intervals`) gives its interval around ``coverage`` again and
        reviews the segment on it (:meth:`~colonbench.completion.intervals.Intervals.apply` with the estimate's
        signals: for the map's segments, whose extent is known, the known-extent quantiles and the map's review
        threshold); one with only ``interval(coverage, signals)`` gives the interval and keeps the estimate's review.
    est : colonbench.estimate.Estimate
        The method's estimate of the segment, with its ``coverage_interval``; left as it is.
    coverage : float
        The map's coverage of the segment, fraction.

    Returns
    -------
    [low, high] : list of float
        Fractions in [0, 1]. A method without a calibration gets its own interval moved by ``coverage -
        est.coverage`` and clipped to [0, 1]; an end it had clipped at 1 moves with it. A ``coverage`` that is not
        finite gets the estimate's interval and review as they are.
    review : list of str
        The segment's review reasons: a calibrated method's decided on the interval around ``coverage``, the interval
        the map reports; any other method's its estimate's, as it gave them.
    """
    cal = getattr(method, "intervals", None)
    if not np.isfinite(coverage):                       # no coverage to put an interval around: the estimate's
        return [float(x) for x in est.coverage_interval], list(est.review)
    if callable(getattr(cal, "apply", None)):
        seg = replace(est, coverage=float(coverage), review=[], signals=dict(est.signals))
        cal.apply(seg)
        return [float(x) for x in seg.coverage_interval], list(seg.review)
    if callable(getattr(cal, "interval", None)):        # a calibration that gives intervals, no review
        return [float(x) for x in cal.interval(coverage, est.signals)], list(est.review)
    shift = coverage - est.coverage
    return [float(np.clip(x + shift, 0, 1)) for x in est.coverage_interval], list(est.review)


def map_colon(points: np.ndarray, method, segment_mm: float = SEGMENT_MM, positions: np.ndarray | None = None,
              progress: bool = True, context_mm: float = 0.0, pieces: list | None = None) -> dict:
    """The coverage map of a reconstruction.

    Parameters
    ----------
    points : (n, 3) float
        The reconstruction, mm.
    method : object
        A coverage-estimation method (``estimate(points)``, see docs/benchmark.md).
    segment_mm : float
        Segment arc length, mm.
    positions : (k, 3) float, optional
        Camera positions in time order, mm, same frame.
    progress : bool
        A progress bar over the segments.
    context_mm : float
        0: each segment estimated on its own points alone (the paper's
        segment-only protocol). Above 0: the method is given the segment's
        points and those up to ``context_mm`` of arc length beyond each plane
        (its neighbours' surface), and its completed mesh is clipped to the
        faces nearest to the segment's stretch of the centerline before the
        coverage is counted; a method without a completed mesh is then run on
        the segment alone.
    pieces : list of colonbench.mapping.lumen_paths.Piece, optional
        ``colon_centerline(points, positions=positions)`` when the caller has it already (several
        methods or tracks mapping the same reconstruction).

    Returns
    -------
    dict
        ``segments`` (list of :class:`Segment`), ``centerline`` ((m, 3) mm),
        ``arclength`` ((m,) mm), ``interruptions`` (list of dicts), ``unreconstructed``
        (stretches with no reconstruction that the trajectory bridges: ``from_mm``, ``to_mm``),
        ``orientation`` (str), ``reached`` (share of the points within the centerline's reach,
        :mod:`colonbench.mapping.reach`), ``seconds`` (per stage).

    Raises
    ------
    InputError
        No tube found, or a colon no longer than two segments (a single
        segment: use ``colonbench estimate``).
    """
    from colonbench.estimate import as_estimate
    from colonbench.errors import ColonbenchError
    from colonbench.progress import bar as progress_bar
    from colonbench.slab import stretch

    if segment_mm <= 0:
        raise InputError(f"--segment-length must be positive, got {segment_mm}")
    if context_mm < 0:
        raise InputError(f"--context-mm must be 0 or more, got {context_mm}")
    seconds = {}
    t0 = time.perf_counter()
    pieces, orientation = map_centerline(points, positions, pieces)
    seconds["centerline"] = time.perf_counter() - t0
    why = single_segment(sum(p.length for p in pieces), segment_mm)
    if why:
        raise InputError(f"{why}; use colonbench estimate for one segment")
    joined = join_pieces(pieces)
    line, arc, spans, unseen = joined.line, joined.arc, joined.spans, joined.unseen
    t0 = time.perf_counter()
    point_s, point_piece = joined.assign(points)
    far = beyond_reach(joined, [p.radius for p in pieces], points)
    segments = []
    for k, (a, b) in enumerate(spans):
        ps, pa = joined.arcs[k], joined.lines[k]
        for lo, hi in windows(b - a, segment_mm):
            lo, hi = a + lo, a + hi
            last = hi >= b - 1e-9
            mine = point_piece == k
            mask = mine & (point_s >= lo) & ((point_s < hi) | (last & (point_s <= hi)))
            # a method that completes no surface has nothing to clip: it is given the segment alone
            ctx = (mine & (point_s >= lo - context_mm) & (point_s <= hi + context_mm)
                   if context_mm > 0 and getattr(method, "completes_surface", True) else mask)
            gap = sum(max(0.0, min(hi, u1) - max(lo, u0)) for u0, u1 in unseen)
            segments.append((Segment(index=len(segments), piece=k, start_mm=lo, end_mm=hi,
                                     plane_start=_frame(pa, ps, lo), plane_end=_frame(pa, ps, hi),
                                     points=int(mask.sum()), unreconstructed_mm=gap), mask, ctx,
                             (pa, ps, last, pieces[k].radius)))
    seconds["cut"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    out = []
    name = getattr(method, "name", "method")
    method = for_mapping(method, context_mm)
    # an in-context model is given the segment's stretch of centerline: in every track when it is the method's
    # model, in the tracks with context when it is its context model
    in_context = bool(getattr(method, "needs_slab", False)) or (context_mm > 0 and getattr(method, "takes_slab", False))
    for seg, mask, ctx, (pa, ps, last, radius) in progress_bar(segments, desc="segments", unit="seg",
                                                                enabled=progress):
        length = seg.end_mm - seg.start_mm
        if seg.points < MIN_POINTS and seg.unreconstructed_mm >= 0.5 * length:
            # the scope passed, nothing was reconstructed: all of it unobserved (a tube of the colon's radius)
            seg.coverage, seg.holes = 0.0, 1
            seg.area_mm2 = seg.hole_area_mm2 = seg.largest_hole_mm2 = float(2 * np.pi * radius * length)
            out.append(seg)
            continue
        if seg.points < MIN_POINTS:
            seg.error, seg.skipped = few_points_error(seg.points, MIN_POINTS), True
            out.append(seg)
            continue
        seg.error = unreached_error(far[mask], 1.0 - float(far.mean()), positions is not None)
        if seg.error:  # mostly points the centerline does not reach: not one segment's cloud
            seg.skipped = True
            out.append(seg)
            continue
        t = time.perf_counter()
        try:
            if in_context:  # an in-context model: given the segment's stretch of centerline
                slab = stretch(pa, ps, seg.start_mm, seg.end_mm, context_mm)
                est = as_estimate(method.estimate(points[ctx], slab=slab), name)
            else:
                est = as_estimate(method.estimate(points[ctx]), name)
            faces = est.mesh_faces
            if (context_mm > 0 or in_context) and len(faces):  # the completed context, clipped to the segment's stretch
                hi = seg.end_mm + (1e-6 if last else 0.0)
                faces = clip_between(est.mesh_vertices, faces, pa, ps, seg.start_mm, hi)
                if len(faces) == 0:
                    raise ColonbenchError("the completed surface holds nothing between the segment's planes")
            elif context_mm > 0:  # no mesh to clip: the segment alone
                est = as_estimate(method.estimate(points[mask]), name)
                faces = est.mesh_faces
        except ColonbenchError as exc:
            seg.error = str(exc)
            out.append(seg)
            continue
        seg.seconds = time.perf_counter() - t
        if not np.isfinite(est.coverage):  # an empty completed surface: no estimate, not a NaN in the sums
            seg.error = "the method returned no coverage (its completed surface is empty): not estimated"
            out.append(seg)
            continue
        seg.coverage = float(est.coverage)
        if len(faces):
            from colonbench.completion.surface import mesh_coverage
            from colonbench.meshes import triangle_areas

            if faces is not est.mesh_faces:
                seg.coverage = mesh_coverage(est.mesh_vertices, faces, est.hole_vertices)
            seg.area_mm2 = float(triangle_areas(est.mesh_vertices, faces).sum())
            seg.hole_area_mm2, regions = hole_regions(est.mesh_vertices, faces, est.hole_vertices)
            seg.holes = int(np.sum(regions >= MIN_HOLE_MM2))
            seg.largest_hole_mm2 = float(regions[0]) if len(regions) else 0.0
            used = np.unique(faces)
            index = np.full(len(est.mesh_vertices), -1)
            index[used] = np.arange(len(used))
            seg.mesh = (est.mesh_vertices[used], index[faces], est.hole_vertices[used])
        if seg.unreconstructed_mm > 0:
            add_unreconstructed(seg, radius)
        seg.review = list(est.review)
        if est.coverage_interval is not None:  # the method's interval and review, around the segment's own coverage
            est.signals["map_track"] = "context" if context_mm > 0 else "segment-only"   # a calibration's map part
            seg.coverage_interval, seg.review = mapped_interval(method, est, seg.coverage)
        out.append(seg)
    review_by_point_rate(out, (getattr(getattr(method, "intervals", None), "map", None) or {}).get("review_point_rate"))
    seconds["estimate"] = time.perf_counter() - t0
    return {"segments": out, "centerline": line, "arclength": arc, "interruptions": joined.interruptions,
            "unreconstructed": [{"from_mm": round(a, 2), "to_mm": round(b, 2)} for a, b in unseen],
            "orientation": orientation, "context_mm": float(context_mm), "reached": 1.0 - float(far.mean()),
            "seconds": seconds}
