"""The steps after the network, in order: the completed surface of a segment from its heatmap, clipped to its planes,
its holes, the wall gaps put back, and its coverage (voxel units; docs/method.md).

:data:`STEPS_VERSION` is the revision of these steps, part of every method's version built on them."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from colonbench.completion.gaps import GAP_VALLEY, reach_planes, wall_gaps
from colonbench.completion.planes import clip_to_segment, segment_planes
from colonbench.completion.surface import (HOLE_DISTANCE, SHELL_LEVEL, clip_to_shell, extract_mesh, hole_vertices,
                                           mesh_coverage, resigned_field)
from colonbench.meshes import triangle_areas
from colonbench.polyline import arc_length


#: Revision of the steps after the network, part of the methods' versions: 1 the paper's, 2 the sparse
#: clouds' hole distance, 3 the cut rims, 4 the shell level, 5 the wall gaps, 6 the centerline's ends on the
#: lumen's far ends and the cut rims held where the line runs past them, 7 an end with no cut rim pushed out to
#: the cloud's extent, 8 the wall gaps' stations run on from the line's ends to planes beyond them, 9 clouds
#: denser than 3 points/mm^2 thinned to 2 before the method runs (:func:`colonbench.completion.method.thin_dense`),
#: 10 a cloud taken as its distinct points in lexicographic order before it is thinned (the thinning's draw
#: depended on the order of the points, and repeated points counted in the cloud's density).
STEPS_VERSION = "10"


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
    rims : int
        How many of them were found at a cut rim of the cloud (:class:`colonbench.completion.planes.Planes`); with
        ``cut_rims`` off, where the caller knows the segment's ends, all of them.
    gap_share : float
        The share of the mesh's area in wall-gap patches (hole surface put where the tube has no wall).
    """

    vertices: np.ndarray
    faces: np.ndarray
    hole: np.ndarray
    coverage: float
    planes: list = field(default_factory=list)
    rims: int = 0
    gap_share: float = 0.0


def complete(heatmap: np.ndarray, centerline_vox: np.ndarray, partial_vox: np.ndarray,
             distance: float | None = None, cut_rims: bool = True,
             shell_level: float | None = SHELL_LEVEL, gaps: bool = True, valley: float = GAP_VALLEY,
             planes: list | None = None, voxel_mm: float = 1.0) -> Completion:
    """Mesh, holes and coverage of a segment from its target heatmap, centerline and partial cloud (voxels).

    ``distance`` is the hole distance in voxels (default: the paper's sqrt(2)/2). ``cut_rims``: clip
    at the cloud's cut rims where they are found (:func:`rim_planes`), else at the centerline's ends.
    ``shell_level``: drop the faces where the heatmap is above it (:func:`clip_to_shell`); None keeps
    every face, as before version 4 of the steps. ``gaps``: add hole patches where the tube has no wall
    (:func:`wall_gaps`), as from version 5; ``valley``: where the heatmap along such a ray falls below this
    (``inf``: every ray that meets no wall, for a surface without faint walls, such as a classical
    reconstruction's). ``planes`` (point, inward normal; voxels): clip at these instead of finding them (a caller
    that knows the segment's ends). ``voxel_mm``: a voxel's edge, mm (the rims' doubt, :func:`rim_planes`).
    """
    verts, faces = extract_mesh(*resigned_field(heatmap, centerline_vox))
    if shell_level is not None:
        verts, faces = clip_to_shell(verts, faces, heatmap, shell_level)
    planes = segment_planes(centerline_vox, partial_vox, cut_rims, voxel_mm) if planes is None else planes
    verts, faces = clip_to_segment(verts, faces, centerline_vox, planes=planes)
    hole = hole_vertices(verts, partial_vox, HOLE_DISTANCE if distance is None else distance)
    gap_share = 0.0
    if gaps and len(faces):
        gap_v, gap_f = wall_gaps(heatmap, centerline_vox, planes, valley=valley)
        faces = np.concatenate([faces, gap_f + len(verts)])
        verts = np.concatenate([verts, gap_v])
        hole = np.concatenate([hole, np.ones(len(gap_v), bool)])
        if len(gap_f):
            area = triangle_areas(verts, faces)
            gap_share = float(area[-len(gap_f):].sum() / area.sum()) if area.sum() > 0 else 0.0
    rims = getattr(planes, "rims", 0) if cut_rims else len(planes)   # planes the caller knows are the segment's ends
    return Completion(verts, faces, hole, mesh_coverage(verts, faces, hole), planes, rims, gap_share)


def signals_of(comp: Completion, line_mm: np.ndarray, inside_vox: np.ndarray, voxel_mm: float, cut_rims: bool) -> dict:
    """What a completed segment says of how sure its estimate is (:attr:`colonbench.estimate.Estimate.signals`).

    Parameters
    ----------
    comp : Completion
        The completed segment, its planes and rims.
    line_mm : (m, 3) float
        The method's centerline between the planes, mm.
    inside_vox : (k, 3) float
        The same line in voxels, before it is resampled.
    voxel_mm : float
        A voxel's edge, mm.
    cut_rims : bool
        Whether the planes were searched for at the cloud's cut rims (else the caller knows them).

    Returns
    -------
    dict
        ``rims``, ``rims_doubtful`` (:class:`~colonbench.completion.planes.Planes`), ``gap_share``, ``length_mm``
        (``line_mm``'s length), ``span_mm`` (the line run on to the planes,
        :func:`~colonbench.completion.gaps.reach_planes`, mm) and, where the planes were searched for, ``rim_fill``:
        the smaller of the two ends' shares of a ring their cut rims fill, 0 where an end has none or no rim was
        searched for (decision record 0175); where the caller knows them, ``extent``: ``known``.
    """
    fill = getattr(comp.planes, "fill", ())
    out = {"rims": int(comp.rims), "rims_doubtful": int(getattr(comp.planes, "doubtful", 0)),
           "gap_share": round(comp.gap_share, 4),
           "length_mm": round(float(arc_length(line_mm)[-1]), 2) if len(line_mm) else 0.0,
           "span_mm": round(float(arc_length(reach_planes(inside_vox, comp.planes))[-1]) * voxel_mm, 2)}
    return {**out, **({"rim_fill": round(min(fill), 4) if fill else 0.0} if cut_rims else {"extent": "known"})}
