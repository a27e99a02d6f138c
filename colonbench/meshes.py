"""Triangle meshes as arrays: face areas, and points drawn uniformly on a surface (mm)."""

from __future__ import annotations

import numpy as np

from colonbench.errors import InputError


def sample_surface(rng: np.random.Generator, vertices, faces, density: float | None = None,
                   count: int | None = None, areas=None) -> np.ndarray:
    """Points drawn uniformly on a triangle surface.

    Parameters
    ----------
    rng : numpy.random.Generator
    vertices : (n, 3) float, mm
    faces : (m, 3) int
    density : float, optional
        Points per mm^2; the count is ``round(density * area)``.
    count : int, optional
        Number of points (instead of ``density``).

    Returns
    -------
    (k, 3) float
    """
    vertices = np.asarray(vertices, float)
    faces = np.asarray(faces, np.int64)
    if len(faces) == 0:
        return np.zeros((0, 3))
    tri = vertices[faces]
    if areas is None:
        areas = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    total = areas.sum()
    if count is None:
        if density is None:
            raise InputError("sample_surface needs a density or a count")
        count = int(round(density * total))
    if count == 0 or total <= 0:
        return np.zeros((0, 3))
    cdf = np.cumsum(areas) / total
    pick = np.minimum(np.searchsorted(cdf, rng.random(count), side="right"), len(faces) - 1)
    u, v = rng.random(count), rng.random(count)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    t = tri[pick]
    return t[:, 0] + u[:, None] * (t[:, 1] - t[:, 0]) + v[:, None] * (t[:, 2] - t[:, 0])


def triangle_areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(f,) triangle areas."""
    v = vertices[faces]
    return 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)
