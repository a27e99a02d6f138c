"""One training/benchmark sample: a segment with one permutation of holes, and its ground truth.

Everything is in millimetres in the colon's frame. The segment-to-voxel-grid
transform is not made here: it is computed from the partial points alone, by
the heatmap stage.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import trimesh

from colonbench.datagen import camera as cam
from colonbench.datagen.config import CameraConfig, SegmentConfig, SphereConfig
from colonbench.datagen.holes import check_hole_model, inside_spheres, sample_spheres, sample_surface
from colonbench.datagen.segments import SegmentSurface, _components


#: How many times holes are drawn at most to reach ``SegmentConfig.min_coverage``.
MAX_HOLE_DRAWS = 20


@dataclass
class Sample:
    """A partial colon segment and its exact ground truth.

    Attributes
    ----------
    complete : trimesh.Trimesh
        The segment's complete surface, mm.
    observed_faces : (f,) bool
        Which faces of ``complete`` the reconstruction has.
    centerline : (m, 3) float
        GT centerline inside the segment, spacing <= 0.5 mm, mm.
    coverage : float
        Observed area / complete area, in [0, 1].
    partial_points : (n, 3) float
        Point cloud sampled on the observed surface (noise added if ``noise_mm > 0``), mm.
    hole_points : (k, 3) float
        Dense samples of the unobserved surface, mm.
    hole_areas : (h,) float
        Area of each hole (connected piece of unobserved faces), mm^2, largest first.
    window : (float, float)
        Arc-length window on the colon's centerline, mm.
    hole_model : str
    noise_mm : float
    info : dict
        Poses or spheres used, JSON-friendly.
    """

    complete: trimesh.Trimesh
    observed_faces: np.ndarray
    centerline: np.ndarray
    coverage: float
    partial_points: np.ndarray
    hole_points: np.ndarray
    hole_areas: np.ndarray
    window: tuple
    hole_model: str
    noise_mm: float
    info: dict = field(default_factory=dict)


def observe(rng, scene: cam.SurfaceScene, centerline, surface: SegmentSurface, hole_model: str,
            camera: CameraConfig, spheres: SphereConfig):
    """Draw one permutation of holes for a segment.

    Returns
    -------
    observed : (f,) bool
        Per face of ``surface.mesh``.
    info : dict
        The poses and/or spheres drawn.
    """
    parts = check_hole_model(hole_model)
    mesh = surface.mesh
    observed = np.ones(len(mesh.faces), dtype=bool)
    info = {}
    if "camera" in parts:
        poses = cam.sample_poses(rng, scene, centerline, surface.window, camera)
        parents = np.unique(surface.parent_face)
        seen = cam.visible_faces(scene, poses, camera.fov_deg, camera.near_mm, candidates=parents)
        observed &= seen[surface.parent_face]
        info["poses"] = {"positions": poses.positions.tolist(), "directions": poses.directions.tolist(),
                         "reach_mm": poses.reach_mm.tolist()}
    if "spheres" in parts:
        areas = mesh.area_faces
        centers, radii = sample_spheres(rng, mesh.vertices, mesh.faces, spheres, areas=areas)
        observed &= ~inside_spheres(mesh.triangles_center, centers, radii)
        info["spheres"] = {"centers": centers.tolist(), "radii": radii.tolist()}
    return observed, info


def observe_covered(rng, scene, centerline, surface: SegmentSurface, hole_model: str, camera: CameraConfig,
                    spheres: SphereConfig, min_coverage: float):
    """:func:`observe`, redrawn until the coverage reaches ``min_coverage`` (at most ``MAX_HOLE_DRAWS`` draws).

    A segment nobody looked at has no reconstruction to estimate from. The
    redraws continue the same stream, so the result stays deterministic.

    Returns
    -------
    observed : (f,) bool
    coverage : float
        Observed area / complete area.
    info : dict
        As :func:`observe`, plus ``hole_draws``.
    """
    areas = surface.mesh.area_faces
    total = areas.sum()
    for attempt in range(MAX_HOLE_DRAWS):
        observed, info = observe(rng, scene, centerline, surface, hole_model, camera, spheres)
        coverage = float(areas[observed].sum() / total) if total > 0 else float("nan")
        if coverage >= min_coverage:
            break
    info["hole_draws"] = attempt + 1
    return observed, coverage, info


def hole_areas(mesh: trimesh.Trimesh, observed: np.ndarray) -> np.ndarray:
    """Areas (mm^2) of the connected pieces of unobserved faces, largest first."""
    holes = np.flatnonzero(~observed)
    if len(holes) == 0:
        return np.zeros(0)
    label = _components(mesh.faces[holes], len(mesh.vertices))
    _, inv = np.unique(label, return_inverse=True)
    areas = np.bincount(inv, weights=mesh.area_faces[holes])
    return np.sort(areas)[::-1]


def make_sample(rng, scene, centerline, surface: SegmentSurface, hole_model: str = "camera",
                camera: CameraConfig | None = None, spheres: SphereConfig | None = None,
                segments: SegmentConfig | None = None, noise_mm: float | None = None) -> Sample:
    """One sample: holes drawn with ``rng``, points sampled, ground truth measured.

    Parameters
    ----------
    rng : numpy.random.Generator
        The stream of this (colon, segment, permutation).
    scene : SurfaceScene
        The whole colon in Embree.
    centerline : Centerline
        The colon's GT centerline.
    surface : SegmentSurface
        From :func:`colonbench.datagen.segments.segment_surface`.
    hole_model : {"camera", "spheres", "camera+spheres"}
    noise_mm : float, optional
        Gaussian noise sigma on the partial points (default: ``segments.noise_mm``).
    """
    camera = camera or CameraConfig()
    spheres = spheres or SphereConfig()
    segments = segments or SegmentConfig()
    noise = segments.noise_mm if noise_mm is None else float(noise_mm)
    mesh = surface.mesh
    areas = mesh.area_faces
    observed, coverage, info = observe_covered(rng, scene, centerline, surface, hole_model, camera, spheres,
                                               segments.min_coverage)
    partial = sample_surface(rng, mesh.vertices, mesh.faces[observed], segments.point_density,
                             areas=areas[observed])
    holes = sample_surface(rng, mesh.vertices, mesh.faces[~observed], segments.hole_point_density,
                           areas=areas[~observed])
    if noise > 0:
        partial = partial + rng.normal(0.0, noise, partial.shape)
    return Sample(mesh, observed, surface.centerline, coverage, partial, holes, hole_areas(mesh, observed),
                  surface.window, hole_model, noise, info)
