"""Centerlines with known geometry for the tests."""

import numpy as np

from colonbench.polyline import Centerline


def distance_to_polyline(points, polyline):
    """Distance of each point (n, 3) to a polyline densified at 0.05 mm, mm."""
    from scipy.spatial import cKDTree

    from colonbench.heatmaps import densify_polyline

    d, _ = cKDTree(densify_polyline(polyline, 0.05)).query(points)
    return d

def straight(length=240.0, spacing=0.5):
    """A straight centerline along +z from the origin."""
    return Centerline.from_function(lambda t: np.stack([0 * t, 0 * t, t], 1), 0.0, length, spacing)


def arc(radius, angle, spacing=0.5):
    """A planar circular arc of ``radius`` (mm) through ``angle`` (rad) in the x-y plane."""
    return Centerline.from_function(
        lambda t: np.stack([radius * np.cos(t), radius * np.sin(t), 0 * t], 1), 0.0, angle, spacing)


def helix(radius=40.0, pitch=60.0, turns=1.5, spacing=0.5):
    """A helix about z and its exact length 2 pi turns sqrt(radius^2 + (pitch / 2 pi)^2)."""
    c = pitch / (2 * np.pi)
    cl = Centerline.from_function(lambda t: np.stack([radius * np.cos(t), radius * np.sin(t), c * t], 1),
                                  0.0, 2 * np.pi * turns, spacing)
    return cl, 2 * np.pi * turns * np.hypot(radius, c)


def capped(colon):
    """Close an open tube from ``tube_colon`` with a fan at each end (a watertight mesh)."""
    import trimesh

    v, f, n = colon.mesh.vertices, colon.mesh.faces, colon.n_around
    k = len(v) // n
    first, last = len(v), len(v) + 1
    ends = np.array([v[:n].mean(axis=0), v[-n:].mean(axis=0)])
    j = np.arange(n)
    cap0 = np.stack([np.full(n, first), (j + 1) % n, j], 1)
    cap1 = np.stack([np.full(n, last), (k - 1) * n + j, (k - 1) * n + (j + 1) % n], 1)
    return trimesh.Trimesh(np.concatenate([v, ends]), np.concatenate([f, cap0, cap1]), process=False)
