"""Tubes swept along a centerline, and the check that a tube never runs into itself.

A tube is given by a centerline (rings at arc lengths ``s_k``), a
rotation-minimising frame and a radius field ``rho[k, j]`` at angle
``theta_j = 2 pi j / n``. Ring ``k`` lies exactly in the plane perpendicular to
the centerline at ``s_k``, so a cross-section of the tube at a ring is exact.
"""

from __future__ import annotations

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from colonbench.polyline import Centerline


def ring_angles(n_around: int) -> np.ndarray:
    """Angles of the ring vertices, radians; (n_around,)."""
    return 2.0 * np.pi * np.arange(n_around) / n_around


def sweep(centerline: Centerline, radius: np.ndarray, frames=None) -> trimesh.Trimesh:
    """Triangle mesh of a tube around ``centerline``.

    Parameters
    ----------
    centerline : Centerline
        K ring centres (mm).
    radius : (K, n) float
        Distance of each ring vertex from its centre, mm.
    frames : tuple of (K, 3) arrays, optional
        ``(tangent, normal, binormal)``; rotation-minimising frames by default.

    Returns
    -------
    trimesh.Trimesh
        Open tube (no caps), ``K * n`` vertices, ``2 (K - 1) n`` faces, normals
        pointing out of the lumen. Vertex ``k * n + j`` is ring ``k``, angle ``j``.
    """
    radius = np.asarray(radius, dtype=np.float64)
    k, n = radius.shape
    if k != len(centerline.points):
        raise ValueError("radius needs one row per centerline point")
    _, nrm, bnm = frames if frames is not None else centerline.frames()
    theta = ring_angles(n)
    direction = np.cos(theta)[None, :, None] * nrm[:, None, :] + np.sin(theta)[None, :, None] * bnm[:, None, :]
    vertices = centerline.points[:, None, :] + radius[:, :, None] * direction
    return trimesh.Trimesh(vertices.reshape(-1, 3), grid_faces(k, n), process=False)


def grid_faces(k: int, n: int) -> np.ndarray:
    """Faces of a closed-around, open-ended grid of ``k`` rings of ``n`` vertices; (2 (k-1) n, 3) int."""
    ring = np.arange(k - 1)[:, None] * n
    j = np.arange(n)[None, :]
    a = ring + j
    b = ring + (j + 1) % n
    c = a + n
    d = b + n
    f1 = np.stack([a, b, c], axis=-1)
    f2 = np.stack([b, d, c], axis=-1)
    return np.stack([f1, f2], axis=2).reshape(-1, 3).astype(np.int64)


def disk_collisions(centers, normals, radii, min_index_gap: int = 1):
    """Pairs of disks that intersect.

    Disk ``i`` has centre ``centers[i]``, unit normal ``normals[i]`` and radius
    ``radii[i]``. For a tube, the disks are its cross-sections (radius = the
    largest radius of the ring plus half the wanted clearance); the tube runs
    into itself, or two loops come closer than the clearance, exactly when two
    cross-sections intersect.

    Parameters
    ----------
    centers : (n, 3) float
    normals : (n, 3) float, unit length
    radii : (n,) float
    min_index_gap : int
        Only pairs with ``j - i >= min_index_gap`` are tested.

    Returns
    -------
    (m, 2) int
        Index pairs ``(i, j)``, ``i < j``, of intersecting disks.
    """
    centers = np.asarray(centers, float)
    normals = np.asarray(normals, float)
    radii = np.asarray(radii, float)
    pairs = cKDTree(centers).query_pairs(2.0 * radii.max(), output_type="ndarray")
    if len(pairs) == 0:
        return np.zeros((0, 2), dtype=np.int64)
    pairs = np.sort(pairs, axis=1)
    pairs = pairs[(pairs[:, 1] - pairs[:, 0]) >= min_index_gap]
    i, j = pairs[:, 0], pairs[:, 1]
    c1, c2, n1, n2, r1, r2 = centers[i], centers[j], normals[i], normals[j], radii[i], radii[j]
    dist = np.linalg.norm(c2 - c1, axis=1)
    near = dist < r1 + r2
    i, j, c1, c2, n1, n2, r1, r2 = (a[near] for a in (i, j, c1, c2, n1, n2, r1, r2))
    hit = np.zeros(len(i), dtype=bool)

    u = np.cross(n1, n2)
    sin2 = np.einsum("ij,ij->i", u, u)
    parallel = sin2 < 1e-12
    # parallel planes: the disks meet only if coplanar and overlapping
    gap = np.abs(np.einsum("ij,ij->i", c2 - c1, n1))
    hit[parallel] = gap[parallel] < 1e-9

    q = ~parallel
    h1 = np.einsum("ij,ij->i", n1[q], c1[q])
    h2 = np.einsum("ij,ij->i", n2[q], c2[q])
    cos = np.einsum("ij,ij->i", n1[q], n2[q])
    den = 1.0 - cos**2
    p0 = (((h1 - h2 * cos) / den)[:, None] * n1[q] + ((h2 - h1 * cos) / den)[:, None] * n2[q])
    d = u[q] / np.sqrt(sin2[q])[:, None]

    def chord(c, r):
        w = p0 - c
        b = np.einsum("ij,ij->i", w, d)
        disc = b**2 - (np.einsum("ij,ij->i", w, w) - r**2)
        root = np.sqrt(np.maximum(disc, 0.0))
        return disc >= 0, -b - root, -b + root

    ok1, lo1, hi1 = chord(c1[q], r1[q])
    ok2, lo2, hi2 = chord(c2[q], r2[q])
    hit[q] = ok1 & ok2 & (np.maximum(lo1, lo2) <= np.minimum(hi1, hi2))
    return np.stack([i[hit], j[hit]], axis=1)


def self_intersections(centerline: Centerline, max_radius: np.ndarray, clearance_mm: float = 0.0,
                       step_mm: float = 1.0) -> np.ndarray:
    """Where a tube of the given largest radii would meet itself (or come closer than ``clearance_mm``).

    Parameters
    ----------
    centerline : Centerline
    max_radius : (n,) float
        Largest distance from the centerline of the tube wall at each centerline
        sample, mm (folds and polyps only reach inwards, so the base radius plus
        the roughness bound is enough).
    clearance_mm : float
        Wanted smallest gap between two parts of the wall.
    step_mm : float
        Arc-length spacing at which cross-sections are tested.

    Returns
    -------
    (m, 2) float
        Arc-length pairs (mm) of the cross-sections that intersect; empty when the
        tube is free of self-intersection.
    """
    n = max(int(np.ceil(centerline.length / step_mm)), 2)
    s = np.linspace(0.0, centerline.length, n + 1)
    centers = centerline.point_at(s)
    normals = centerline.tangent_at(s)
    radii = np.interp(s, centerline.arclength, max_radius) + 0.5 * clearance_mm
    pairs = disk_collisions(centers, normals, radii, min_index_gap=1)
    return s[pairs] if len(pairs) else np.zeros((0, 2))
