"""Hole models: what part of a segment's surface a reconstruction misses.

Two models, which can be combined (a face is observed only if every model in
use keeps it):

- ``camera``: the virtual colonoscope of :mod:`colonbench.datagen.camera`; the
  observed surface is what a few random poses see, occlusion included.
- ``spheres``: the paper's recipe for CT colons; random spheres centred on the
  segment surface are cut out. A face is removed when its centroid lies inside
  a sphere: faces are at most about 1 mm across, so the decision is exact to
  the mesh resolution and the area that remains is summed exactly.
- ``end`` (only with one of the others): one end of the segment was never
  seen, as after a withdrawal that never looked back. The faces within a drawn
  share (``SegmentConfig.unseen_end``) of the segment's arc length from one
  end, drawn too, are removed.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from colonbench.datagen import HOLE_MODELS
from colonbench.datagen.config import SphereConfig
from colonbench.errors import InputError
from colonbench.meshes import sample_surface
from colonbench.params import draw


def check_hole_model(name: str) -> tuple[str, ...]:
    """The parts of a hole-model name (``"camera+spheres"`` -> ``("camera", "spheres")``)."""
    if name not in HOLE_MODELS:
        raise InputError(f"unknown hole model {name!r}; choose one of {list(HOLE_MODELS)}")
    return tuple(name.split("+"))


def sample_spheres(rng: np.random.Generator, vertices, faces, config: SphereConfig, areas=None):
    """Draw crop spheres centred on random surface points (area-weighted).

    Returns
    -------
    centers : (k, 3) float, mm
    radii : (k,) float, mm
    """
    n = draw(rng, config.spheres, integer=True)
    if n == 0 or len(faces) == 0:
        return np.zeros((0, 3)), np.zeros(0)
    centers = sample_surface(rng, vertices, faces, count=n, areas=areas)
    radii = rng.uniform(config.radius_mm[0], config.radius_mm[1], n)
    return centers, radii


def unseen_end(rng: np.random.Generator, points, centerline, share) -> tuple[np.ndarray, dict]:
    """Which points lie in the unseen end of a segment.

    Parameters
    ----------
    rng : numpy.random.Generator
    points : (n, 3) float
        Face centroids, mm.
    centerline : (m, 3) float
        The segment's centerline, first point at the segment's start, mm.
    share : (float, float)
        Range of the unseen share of the segment's arc length.

    Returns
    -------
    unseen : (n,) bool
    info : dict
        ``end`` ("start" or "end") and ``share``.
    """
    cl = np.asarray(centerline, float)
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(cl, axis=0), axis=1))])
    _, nearest = cKDTree(cl).query(np.asarray(points, float))
    frac = s[nearest] / max(s[-1], 1e-12)
    at_start = bool(rng.random() < 0.5)
    cut = float(rng.uniform(*share))
    unseen = frac < cut if at_start else frac > 1.0 - cut
    return unseen, {"end": "start" if at_start else "end", "share": cut}


def inside_spheres(points, centers, radii) -> np.ndarray:
    """Whether each of (n, 3) points lies inside any sphere; (n,) bool."""
    points = np.asarray(points, float)
    out = np.zeros(len(points), dtype=bool)
    if len(centers) == 0:
        return out
    tree = cKDTree(points)
    for c, r in zip(centers, radii):
        idx = tree.query_ball_point(c, r)
        out[idx] = True
    return out


