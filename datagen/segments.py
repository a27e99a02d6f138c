"""Colon segments: the surface between two cross-sections perpendicular to the centerline.

A segment ``[s0, s1]`` (arc length, mm) is bounded by the plane through
``c(s0)`` normal to the tangent ``t(s0)`` and the plane through ``c(s1)`` normal
to ``t(s1)``. Its surface is found in three steps:

1. *candidates*: faces that reach between the two planes;
2. *no leaks*: the candidates fall into connected pieces (through shared
   vertices). A neighbouring loop of the colon that crosses the region between
   the planes is a piece of its own, because it enters and leaves through the
   planes. Rays cast from this segment's own centerline, perpendicular to it,
   meet this segment's wall first; only the pieces they hit are kept;
3. *nearest stretch*: at a strong bend the two planes form a wedge whose far
   side can hold wall of a neighbouring stretch that is connected to this
   segment's wall (a caecum pole, the outer side of a flexure). A kept face
   whose nearest centerline point lies more than ``margin_mm`` outside the
   window belongs to that other stretch and is dropped;
4. *exact areas*: the kept faces are clipped at both planes (triangles split
   along the planes), so the segment area is exact for the mesh.

Each clipped face remembers its parent face of the colon mesh, so any per-face
label of the colon (seen or not) carries over to the segment.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import trimesh
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from colonbench.errors import ColonbenchError
from colonbench.polyline import Centerline, perpendicular_basis


@dataclass
class SegmentSurface:
    """The complete surface of one segment.

    Attributes
    ----------
    mesh : trimesh.Trimesh
        Clipped surface, mm (not welded across the cut edges).
    parent_face : (f,) int
        Face of the colon mesh each face of ``mesh`` was cut from.
    window : (float, float)
        Arc-length window ``(s0, s1)``, mm.
    centerline : (m, 3) float
        GT centerline inside the window, mm, end points included.
    """

    mesh: trimesh.Trimesh
    parent_face: np.ndarray
    window: tuple
    centerline: np.ndarray
    info: dict = field(default_factory=dict)

    @property
    def area(self) -> float:
        """Surface area, mm^2."""
        return float(self.mesh.area)


def windows(length_mm: float, segment_mm: float, end_margin_mm: float = 0.0) -> list[tuple[float, float]]:
    """Consecutive arc-length windows of ``segment_mm`` along a centerline of ``length_mm``.

    The windows are centred in ``[end_margin, length - end_margin]``; the
    remainder shorter than one segment is split between both ends.
    """
    usable = length_mm - 2.0 * end_margin_mm
    n = int(np.floor(usable / segment_mm + 1e-9))
    if n <= 0:
        return []
    start = end_margin_mm + 0.5 * (usable - n * segment_mm)
    return [(start + i * segment_mm, start + (i + 1) * segment_mm) for i in range(n)]


def clip_faces(vertices, faces, parent, origin, normal):
    """Keep the part of a triangle soup on the positive side of a plane.

    Parameters
    ----------
    vertices : (n, 3) float
    faces : (m, 3) int
    parent : (m,) int
        A label carried by each face to its pieces.
    origin, normal : (3,) float
        The plane; the kept side is ``(x - origin) . normal >= 0``.

    Returns
    -------
    vertices, faces, parent
        The clipped soup. Vertices created on the plane are shared by the faces
        on either side of the same cut edge.
    """
    vertices = np.asarray(vertices, float)
    faces = np.asarray(faces, np.int64)
    dist = (vertices - origin) @ normal
    inside = dist[faces] >= 0
    count = inside.sum(axis=1)
    keep_whole = count == 3
    out_faces = [faces[keep_whole]]
    out_parent = [parent[keep_whole]]
    new_vertices = [vertices]
    n_vert = len(vertices)

    # straddling faces, rotated so that the odd vertex comes first
    cut = (count == 1) | (count == 2)
    if cut.any():
        f = faces[cut]
        ins = inside[cut]
        odd_is_inside = ins.sum(axis=1) == 1
        odd = np.where(odd_is_inside, np.argmax(ins, axis=1), np.argmin(ins, axis=1))
        order = (odd[:, None] + np.arange(3)[None, :]) % 3
        f = np.take_along_axis(f, order, axis=1)   # f[:, 0] is the odd vertex; orientation kept
        a, b, c = f[:, 0], f[:, 1], f[:, 2]
        # the cut points on edges (a, b) and (a, c), shared through an edge key
        edges = np.concatenate([np.stack([a, b], 1), np.stack([a, c], 1)])
        key = np.sort(edges, axis=1)
        uniq, inv = np.unique(key, axis=0, return_inverse=True)
        da, db = dist[uniq[:, 0]], dist[uniq[:, 1]]
        w = da / (da - db)
        pts = vertices[uniq[:, 0]] + w[:, None] * (vertices[uniq[:, 1]] - vertices[uniq[:, 0]])
        new_vertices.append(pts)
        inv = inv.reshape(-1) + n_vert
        p_ab, p_ac = inv[: len(f)], inv[len(f):]
        par = parent[cut]
        one = odd_is_inside
        out_faces.append(np.stack([a[one], p_ab[one], p_ac[one]], 1))
        out_parent.append(par[one])
        two = ~one
        out_faces.append(np.stack([p_ab[two], b[two], c[two]], 1))
        out_faces.append(np.stack([p_ab[two], c[two], p_ac[two]], 1))
        out_parent += [par[two], par[two]]
    return np.concatenate(new_vertices), np.concatenate(out_faces), np.concatenate(out_parent)


def _components(faces, n_vertices):
    """Connected pieces of a face set (through shared vertices): a label per face."""
    if len(faces) == 0:
        return np.zeros(0, dtype=np.int64)
    rows = np.concatenate([faces[:, 0], faces[:, 1]])
    cols = np.concatenate([faces[:, 1], faces[:, 2]])
    graph = coo_matrix((np.ones(len(rows), dtype=np.int8), (rows, cols)), shape=(n_vertices, n_vertices))
    _, label = connected_components(graph, directed=False)
    return label[faces[:, 0]]


#: A face between the planes whose nearest centerline point is farther than this outside the window is
#: another stretch's wall, mm.
STRETCH_MARGIN_MM = 20.0


def segment_surface(scene, centerline: Centerline, s0: float, s1: float,
                    n_ray_rings: int = 24, n_ray_dirs: int = 16, min_hit_share: float = 0.02,
                    margin_mm: float = STRETCH_MARGIN_MM) -> SegmentSurface:
    """Cut the surface of the segment ``[s0, s1]`` out of a colon.

    Parameters
    ----------
    scene : SurfaceScene
        The colon mesh in Embree.
    centerline : Centerline
    s0, s1 : float
        Arc-length window, mm.
    n_ray_rings, n_ray_dirs : int
        Rays cast from ``n_ray_rings`` centerline points inside the window in
        ``n_ray_dirs`` directions each, to recognise this segment's own wall.
    min_hit_share : float
        A connected piece is kept when it receives at least this share of the rays.
    margin_mm : float
        Faces nearest to the centerline more than this outside the window are dropped (step 3).

    Returns
    -------
    SegmentSurface
    """
    if not 0.0 <= s0 < s1 <= centerline.length + 1e-9:
        raise ValueError(f"segment window [{s0}, {s1}] is outside the centerline [0, {centerline.length:.1f}]")
    c0, c1 = centerline.point_at([s0, s1])
    t0, t1 = centerline.tangent_at([s0, s1])
    V, F = scene.vertices, scene.faces
    d0 = (V - c0) @ t0
    d1 = (c1 - V) @ t1
    # faces that reach past both planes into the region between them (a long
    # triangle may span the whole segment without a vertex inside it)
    p0, p1 = d0 >= 0, d1 >= 0
    fa, fb, fc = F[:, 0], F[:, 1], F[:, 2]  # column by column: numpy reduces a short last axis slowly
    cand = np.flatnonzero((p0[fa] | p0[fb] | p0[fc]) & (p1[fa] | p1[fb] | p1[fc]))
    label = _components(F[cand], len(V))

    # rays from the segment's own centerline, perpendicular to it
    s = np.linspace(s0, s1, n_ray_rings + 2)[1:-1]
    origin = centerline.point_at(s)
    tangent = centerline.tangent_at(s)
    u, v = perpendicular_basis(tangent)
    ang = 2 * np.pi * (np.arange(n_ray_dirs) + 0.5) / n_ray_dirs
    dirs = (np.cos(ang)[None, :, None] * u[:, None, :] + np.sin(ang)[None, :, None] * v[:, None, :]).reshape(-1, 3)
    orig = np.repeat(origin, n_ray_dirs, axis=0)
    _, hit = scene.cast(orig, dirs)
    pos = np.full(len(F), -1, dtype=np.int64)
    pos[cand] = np.arange(len(cand))
    hit_local = pos[hit[hit >= 0]]
    hit_local = hit_local[hit_local >= 0]
    counts = np.bincount(label[hit_local], minlength=label.max() + 1 if len(label) else 0)
    keep_labels = np.flatnonzero(counts >= max(1, min_hit_share * len(dirs)))
    kept = cand[np.isin(label, keep_labels)]
    if len(kept):
        _, s_near = centerline.closest(scene.centroids[kept])
        kept = kept[(s_near >= s0 - margin_mm) & (s_near <= s1 + margin_mm)]

    if len(kept) == 0:
        raise ColonbenchError(
            f"segment [{s0:.1f}, {s1:.1f}] mm has no surface: no ray from the centerline meets the wall there "
            "(is the centerline inside the mesh?)")
    verts, faces, parent = clip_faces(V, F[kept], kept, c0, t0)
    verts, faces, parent = clip_faces(verts, faces, parent, c1, -t1)
    # drop vertices no face uses
    used, faces = np.unique(faces, return_inverse=True)
    mesh = trimesh.Trimesh(verts[used], faces.reshape(-1, 3), process=False)
    info = {"pieces_between_planes": int(len(np.unique(label))) if len(label) else 0,
            "pieces_kept": int(len(keep_labels))}
    return SegmentSurface(mesh, parent, (float(s0), float(s1)), centerline.window(s0, s1), info)
