"""A map's segments: what the map keeps of each (the row of segments.json / .csv), its holes, and the whole
colon's coverage from them."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: Hole regions smaller than this are not counted in ``holes`` (specks between the cloud's points), mm^2.
MIN_HOLE_MM2 = 10.0


@dataclass
class Segment:
    """One segment of the map (mm, the input's frame).

    Attributes
    ----------
    index : int
        From 0 at the rectum end (or at the first end when the direction is unknown).
    start_mm, end_mm : float
        Arc lengths along the map's centerline.
    plane_start, plane_end : dict
        ``{"point": [x, y, z], "normal": [x, y, z]}``, normals along increasing arc length.
    points : int
        Reconstruction points in the segment.
    coverage : float or None
        The method's estimate; None when it could not run (``error`` says why).
    hole_area_mm2, largest_hole_mm2 : float or None
        From the completed mesh (None for methods without one).
    holes : int or None
        Hole regions of at least :data:`MIN_HOLE_MM2` on the completed mesh.
    coverage_interval : [float, float] or None
        The method's interval around the coverage (completion: 90 %), where it gives one.
    review : list of str
        Why the segment's estimate should be looked at again (the method's reasons); empty when none.
    """

    index: int
    piece: int
    start_mm: float
    end_mm: float
    plane_start: dict
    plane_end: dict
    points: int
    coverage: float | None = None
    hole_area_mm2: float | None = None
    holes: int | None = None
    largest_hole_mm2: float | None = None
    area_mm2: float | None = None
    seconds: float = 0.0
    error: str = ""
    #: The map gave the segment to no method (too few points, or points beyond its centerline's reach): ``error``
    #: says why; no method's failure.
    skipped: bool = False
    mesh: tuple = field(default=(), repr=False)
    #: Arc length of the segment that the trajectory passes with no reconstruction, mm (counted unobserved).
    unreconstructed_mm: float = 0.0
    coverage_interval: list | None = None
    review: list = field(default_factory=list)

    def row(self) -> dict:
        """The JSON / CSV row."""
        return {"index": self.index, "piece": self.piece, "start_mm": round(self.start_mm, 2),
                "end_mm": round(self.end_mm, 2), "plane_start": self.plane_start, "plane_end": self.plane_end,
                "points": self.points, "coverage": round_or_none(self.coverage, 4),
                "coverage_interval": None if self.coverage_interval is None else [round(x, 4) for x in
                                                                                  self.coverage_interval],
                "review": list(self.review),
                "hole_area_mm2": round_or_none(self.hole_area_mm2, 1), "holes": self.holes,
                "largest_hole_mm2": round_or_none(self.largest_hole_mm2, 1), "area_mm2": round_or_none(self.area_mm2, 1),
                "unreconstructed_mm": round(self.unreconstructed_mm, 1), "seconds": round(self.seconds, 3),
                "error": self.error}


#: What the map says of a segment it does not give the method (the same for every method): too few points, or points
#: mostly beyond its centerline's reach (:mod:`colonbench.mapping.reach`). Read only from results written before
#: :attr:`Segment.skipped` was recorded; a method's own error may say anything.
SKIPPED_BY_MAP = ("points, fewer than", "beyond the reach of the map's centerline")


def few_points_error(points: int, minimum: int) -> str:
    """The ``error`` of a segment with fewer than ``minimum`` reconstruction points: not given to the method."""
    return f"{points} points, fewer than {minimum}: not estimated"


def skipped_by_map(error: str) -> bool:
    """Whether a segment's ``error`` says the map did not give it to the method (:data:`SKIPPED_BY_MAP`), as
    opposed to the method failing on it: for rows written before :attr:`Segment.skipped` was recorded."""
    return any(phrase in str(error or "") for phrase in SKIPPED_BY_MAP)

def round_or_none(x, nd):
    return None if x is None or not np.isfinite(x) else round(float(x), nd)


def hole_regions(vertices: np.ndarray, faces: np.ndarray, hole: np.ndarray) -> tuple[float, np.ndarray]:
    """Hole area and the area of each hole region of a completed mesh, mm^2.

    Each triangle counts its area times its share of hole vertices (as
    :func:`colonbench.completion.surface.mesh_coverage` does); a region is a
    set of triangles with a hole vertex joined by shared edges.

    Returns
    -------
    total : float
    regions : (r,) float, largest first
    """
    import trimesh

    from colonbench.meshes import triangle_areas

    if len(faces) == 0:
        return 0.0, np.zeros(0)
    share = hole[faces].mean(axis=1)
    area = triangle_areas(vertices, faces) * share
    holed = np.flatnonzero(share > 0)
    if len(holed) == 0:
        return 0.0, np.zeros(0)
    adjacency = trimesh.graph.face_adjacency(faces[holed])
    groups = trimesh.graph.connected_components(adjacency, nodes=np.arange(len(holed)), min_len=1)
    regions = np.sort([float(area[holed[g]].sum()) for g in groups])[::-1]
    return float(area.sum()), regions


def add_unreconstructed(seg: Segment, radius: float) -> None:
    """Count the segment's stretch with no reconstruction (the trajectory passes it) as unobserved.

    The method estimated the reconstructed part; the stretch it could not see
    adds a tube of the colon's ``radius`` and its length to the area, all of it
    hole: coverage = observed / (estimated area + that tube).
    """
    gap_area = float(2 * np.pi * radius * seg.unreconstructed_mm)
    seen_length = max(seg.end_mm - seg.start_mm - seg.unreconstructed_mm, 1e-6)
    area = seg.area_mm2 if seg.area_mm2 else float(2 * np.pi * radius * seen_length)
    hole = seg.hole_area_mm2 if seg.hole_area_mm2 is not None else (1.0 - seg.coverage) * area
    seg.coverage = float((area - hole) / (area + gap_area))
    if seg.area_mm2:
        seg.area_mm2, seg.hole_area_mm2 = area + gap_area, hole + gap_area
        seg.largest_hole_mm2 = max(seg.largest_hole_mm2 or 0.0, gap_area)


def whole_coverage(segments: list[Segment]) -> float | None:
    """Observed over completed area over all estimated segments (coverage weighted by length without meshes)."""
    done = [s for s in segments if s.coverage is not None]
    if not done:
        return None
    if all(s.area_mm2 for s in done):
        area = sum(s.area_mm2 for s in done)
        return float(sum(s.area_mm2 - s.hole_area_mm2 for s in done) / area)
    length = np.array([s.end_mm - s.start_mm for s in done])
    return float(np.sum(length * [s.coverage for s in done]) / length.sum())


