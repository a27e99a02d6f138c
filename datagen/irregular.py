"""Diverticula and pedunculated polyps, by constructive solid geometry on the lumen solid (manifold3d).

The paper names both as untested irregularities. A swept tube
(:mod:`colonbench.datagen.tube`) cannot make them: a diverticulum is an
outpouching with a neck, a pedunculated polyp a head on a stalk, and neither
is a radius field over (arc length, angle). So the lumen is closed into a solid
(the tube capped at both ends), and

- a diverticulum is the union with a ball of radius ``r`` whose centre lies
  ``neck * r`` outside the wall (``neck = 0``: a hemisphere opening onto the
  lumen; larger values: a narrower neck, a deeper pouch);
- a pedunculated polyp is the difference with a stalk (a cylinder from just
  outside the wall into the lumen) and a ball at its end.

manifold3d does the Booleans exactly on the triangle meshes and guarantees a
manifold result; the caps are removed again afterwards, so the colon stays an
open tube whose normals point out of the lumen.
"""

from __future__ import annotations

import numpy as np
import trimesh

from colonbench.errors import ColonbenchError

#: Edge length of the balls and cylinders added, mm (the colon's own faces are about 1 mm).
EDGE_MM = 0.8


def _segments(radius: float) -> int:
    return int(max(16, np.ceil(2 * np.pi * radius / EDGE_MM)))


def capped_solid(vertices: np.ndarray, faces: np.ndarray, n_around: int):
    """The manifold3d solid of a swept tube closed by a fan at each end ring.

    Parameters
    ----------
    vertices : (K * n, 3) float
        Ring-ordered tube vertices (vertex ``k * n + j``), mm.
    faces : (f, 3) int
        Tube faces, normals out of the lumen.
    n_around : int
        Vertices per ring.
    """
    import manifold3d as m3

    v = np.asarray(vertices, float)
    k = len(v) // n_around
    first, last = len(v), len(v) + 1
    j = np.arange(n_around)
    cap0 = np.stack([np.full(n_around, first), (j + 1) % n_around, j], 1)
    cap1 = np.stack([np.full(n_around, last), (k - 1) * n_around + j, (k - 1) * n_around + (j + 1) % n_around], 1)
    verts = np.concatenate([v, v[:n_around].mean(axis=0, keepdims=True), v[-n_around:].mean(axis=0, keepdims=True)])
    tris = np.concatenate([faces, cap0, cap1]).astype(np.uint32)
    solid = m3.Manifold(m3.Mesh(vert_properties=verts.astype(np.float32), tri_verts=tris))
    if solid.status() != m3.Error.NoError:
        raise ColonbenchError(f"the lumen is not a closed solid for CSG ({solid.status()})")
    return solid


def _along(direction: np.ndarray) -> np.ndarray:
    """(3, 4) affine turning +z onto ``direction`` (unit)."""
    z = np.array([0.0, 0.0, 1.0])
    d = direction / np.linalg.norm(direction)
    axis = np.cross(z, d)
    s, c = np.linalg.norm(axis), float(z @ d)
    if s < 1e-12:
        rot = np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    else:
        rot = trimesh.transformations.rotation_matrix(np.arctan2(s, c), axis / s)[:3, :3]
    return np.hstack([rot, np.zeros((3, 1))])


def diverticulum(point, normal, radius: float, neck: float):
    """The ball of a diverticulum at wall ``point`` (mm) with outward unit ``normal``; union it with the lumen."""
    import manifold3d as m3

    centre = np.asarray(point, float) + neck * radius * np.asarray(normal, float)
    return m3.Manifold.sphere(radius, _segments(radius)).translate(tuple(centre))


def pedunculated_polyp(point, normal, head_radius: float, stalk_length: float, stalk_radius: float):
    """Stalk and head of a polyp on the wall at ``point`` (mm), ``normal`` out of the lumen; subtract from the lumen."""
    import manifold3d as m3

    p, n = np.asarray(point, float), np.asarray(normal, float) / np.linalg.norm(normal)
    start = p + 2.0 * n                      # from just outside the wall, so that the wall is cut cleanly
    length = stalk_length + 2.0
    stalk = m3.Manifold.cylinder(length, stalk_radius, stalk_radius, _segments(stalk_radius))
    stalk = stalk.transform(_along(-n)).translate(tuple(start))
    head = m3.Manifold.sphere(head_radius, _segments(head_radius))
    head = head.translate(tuple(p - (stalk_length + 0.8 * head_radius) * n))
    return stalk + head


def apply(vertices: np.ndarray, faces: np.ndarray, n_around: int, ring_points: np.ndarray, tangents: np.ndarray,
          pouches: list, polyps: list) -> trimesh.Trimesh:
    """The tube with diverticula added and pedunculated polyps cut in, caps removed again.

    Parameters
    ----------
    vertices, faces, n_around
        The swept tube (:func:`capped_solid`).
    ring_points : (2, 3) float
        Centres of the first and last ring, mm.
    tangents : (2, 3) float
        Unit tangents of the centerline there.
    pouches : list of (point, normal, radius, neck)
    polyps : list of (point, normal, head_radius, stalk_length, stalk_radius)

    Returns
    -------
    trimesh.Trimesh
        Open tube, normals out of the lumen.
    """
    solid = capped_solid(vertices, faces, n_around)
    for p in pouches:
        solid = solid + diverticulum(*p)
    for p in polyps:
        solid = solid - pedunculated_polyp(*p)
    mesh = solid.to_mesh()
    v = np.asarray(mesh.vert_properties[:, :3], float)
    f = np.asarray(mesh.tri_verts, np.int64)
    # drop the caps: faces lying in the end planes
    on_cap = np.zeros(len(f), bool)
    for c, t in zip(ring_points, tangents):
        d = np.abs((v - c) @ t)
        on_cap |= (d[f] < 1e-3).all(axis=1)
    out = trimesh.Trimesh(v, f[~on_cap], process=False)
    used = np.unique(out.faces)
    remap = np.full(len(v), -1, np.int64)
    remap[used] = np.arange(len(used))
    return trimesh.Trimesh(v[used], remap[out.faces], process=False)
