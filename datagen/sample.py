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
from colonbench.datagen.config import CameraConfig, SegmentConfig, SphereConfig, VideoConfig
from colonbench.datagen.holes import check_hole_model, inside_spheres, sample_spheres, unseen_end
from colonbench.datagen.segments import SegmentSurface, _components
from colonbench.errors import InputError
from colonbench.meshes import sample_surface
from colonbench.params import draw


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
            camera: CameraConfig, spheres: SphereConfig, segments: SegmentConfig | None = None):
    """Draw one permutation of holes for a segment.

    Returns
    -------
    observed : (f,) bool
        Per face of ``surface.mesh``.
    info : dict
        The poses, spheres and/or unseen end drawn.
    """
    parts = check_hole_model(hole_model)
    segments = segments or SegmentConfig()
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
    if "end" in parts:
        unseen, info["end"] = unseen_end(rng, mesh.triangles_center, surface.centerline, segments.unseen_end)
        observed &= ~unseen
    return observed, info


def observe_covered(rng, scene, centerline, surface: SegmentSurface, hole_model: str, camera: CameraConfig,
                    spheres: SphereConfig, min_coverage: float, segments: SegmentConfig | None = None):
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
    (observed, info), coverage, draws = _until_covered(
        lambda: observe(rng, scene, centerline, surface, hole_model, camera, spheres, segments),
        surface.mesh.area_faces, min_coverage, MAX_HOLE_DRAWS)
    info["hole_draws"] = draws
    return observed, coverage, info


def _until_covered(draw, areas, min_coverage: float, max_draws: int, usable=None):
    """Call ``draw()`` until what it observed covers ``min_coverage`` of the area, at most ``max_draws`` times.

    Parameters
    ----------
    draw : callable
        Returns a tuple whose first item is the (f,) bool observed mask.
    areas : (f,) float
        Face areas, mm^2.
    usable : callable, optional
        A draw must also satisfy ``usable(result)``.

    Returns
    -------
    result : tuple
        The last draw's.
    coverage : float
        Its observed area / complete area.
    draws : int
    """
    total = areas.sum()
    for attempt in range(max_draws):
        result = draw()
        coverage = float(areas[result[0]].sum() / total) if total > 0 else float("nan")
        if coverage >= min_coverage and (usable is None or usable(result)):
            break
    return result, coverage, attempt + 1


#: How many times a ``video`` withdrawal is drawn at most to reach ``SegmentConfig.min_coverage`` (each costs
#: a rendered and fused video).
MAX_VIDEO_DRAWS = 3
#: Hole models whose partial surface a later package makes, by name: ``video`` is registered by
#: :mod:`colonbench.video` when it is imported (:func:`register_partial_maker`).
PARTIAL_MAKERS: dict = {}


def register_partial_maker(name: str, maker) -> None:
    """Let a package make the partial surface of hole model ``name``.

    ``maker(rng, scene, centerline, surface, config, spread_mm, point_density)`` returns ``(observed faces,
    partial points, info)`` (:func:`colonbench.video.fusion.video_partial`).
    """
    PARTIAL_MAKERS[name] = maker


def _video_covered(rng, scene, centerline, surface: SegmentSurface, camera: CameraConfig,
                   segments: SegmentConfig, video: VideoConfig):
    """The ``video`` hole model (registered by :mod:`colonbench.video`), redrawn up to ``MAX_VIDEO_DRAWS`` times
    until the coverage reaches ``segments.min_coverage``."""
    maker = PARTIAL_MAKERS.get("video")
    if maker is None:
        raise InputError("the video hole model is made by colonbench.video: import colonbench.video first "
                         "(colonbench generate and colonbench segments do)")
    (observed, partial, info), coverage, draws = _until_covered(
        lambda: maker(rng, scene, centerline, surface, video, camera.spread_mm, segments.point_density),
        surface.mesh.area_faces, segments.min_coverage, MAX_VIDEO_DRAWS, usable=lambda r: len(r[1]) > 0)
    return observed, coverage, partial, {"video": info, "hole_draws": draws}


def hole_areas(mesh: trimesh.Trimesh, observed: np.ndarray) -> np.ndarray:
    """Areas (mm^2) of the connected pieces of unobserved faces, largest first."""
    holes = np.flatnonzero(~observed)
    if len(holes) == 0:
        return np.zeros(0)
    label = _components(mesh.faces[holes], len(mesh.vertices))
    _, inv = np.unique(label, return_inverse=True)
    areas = np.bincount(inv, weights=mesh.area_faces[holes])
    return np.sort(areas)[::-1]


def _realistic(segments: SegmentConfig) -> bool:
    """Whether any of the reconstruction flaws of :func:`reconstruction_cloud` is switched on."""
    return (tuple(segments.point_density_scale) != (1.0, 1.0) or segments.density_falloff[1] > 0
            or segments.outlier_share[1] > 0 or segments.double_layer_share[1] > 0)


def _log_uniform(rng, lo_hi) -> float:
    lo, hi = lo_hi
    return float(np.exp(rng.uniform(np.log(lo), np.log(hi)))) if hi > lo else float(lo)


def reconstruction_cloud(rng, mesh: trimesh.Trimesh, observed: np.ndarray, surface: SegmentSurface,
                         segments: SegmentConfig, info: dict) -> tuple[np.ndarray, dict]:
    """A partial cloud with the flaws of real reconstructions (before Gaussian noise).

    1. density: ``point_density`` times a log-uniform draw of ``point_density_scale``;
    2. non-uniform density: each observed face is sampled in proportion to its
       area times ``(d_min / d)^falloff``, ``d`` its distance to the nearest
       camera position (sphere holes: to three random points of the segment's
       centerline), as a camera's pixels spread with depth; the expected count
       stays density x observed area;
    3. a second layer: the ``double_layer_share`` of the points nearest to a
       random point, moved by ``double_layer_offset_mm`` in a random direction
       and turned by up to 2 degrees about the patch's centre (a drifted
       revisit fused twice);
    4. outliers: ``outlier_share`` of the count, each a random point moved
       ``outlier_distance_mm`` in a random direction.

    Returns
    -------
    points : (n, 3) float, mm
    info : dict
        What was drawn.
    """
    V, F = mesh.vertices, mesh.faces[observed]
    areas = mesh.area_faces[observed]
    density = segments.point_density * _log_uniform(rng, segments.point_density_scale)
    falloff = draw(rng, segments.density_falloff)
    weights = areas
    if falloff > 0 and len(F):
        if "poses" in info:
            views = np.asarray(info["poses"]["positions"], float)
        else:
            cl = np.asarray(surface.centerline, float)
            views = cl[rng.integers(0, len(cl), 3)]
        cent = V[F].mean(axis=1)
        d = np.min(np.linalg.norm(cent[:, None, :] - views[None, :, :], axis=2), axis=1)
        d = np.maximum(d, 2.0)
        weights = areas * (d.min() / d) ** falloff
    count = int(round(density * areas.sum()))
    pts = sample_surface(rng, V, F, count=count, areas=weights) if count > 0 else np.zeros((0, 3))
    out = {"density": density, "falloff": falloff, "points": int(len(pts))}
    share = draw(rng, segments.double_layer_share)
    if share > 0 and len(pts) > 10:
        from scipy.spatial import cKDTree

        k = max(1, int(round(share * len(pts))))
        centre = pts[rng.integers(len(pts))]
        _, idx = cKDTree(pts).query(centre, k=k)
        patch = pts[np.atleast_1d(idx)]
        shift = _unit(rng) * draw(rng, segments.double_layer_offset_mm)
        angle = np.radians(rng.uniform(-2.0, 2.0))
        rot = trimesh.transformations.rotation_matrix(angle, _unit(rng))[:3, :3]
        mid = patch.mean(axis=0)
        pts = np.concatenate([pts, (patch - mid) @ rot.T + mid + shift])
        out.update(double_layer_points=int(k), double_layer_shift_mm=float(np.linalg.norm(shift)))
    share = draw(rng, segments.outlier_share)
    if share > 0 and len(pts):
        k = int(round(share * len(pts)))
        base = pts[rng.integers(0, len(pts), k)]
        dist = rng.uniform(*segments.outlier_distance_mm, k)
        pts = np.concatenate([pts, base + _unit(rng, k) * dist[:, None]])
        out["outliers"] = k
    return pts, out


def _unit(rng, n: int | None = None) -> np.ndarray:
    """Random unit vector(s), uniform on the sphere; (3,) or (n, 3)."""
    v = rng.normal(size=(1 if n is None else n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return v[0] if n is None else v


def make_sample(rng, scene, centerline, surface: SegmentSurface, hole_model: str = "camera",
                camera: CameraConfig | None = None, spheres: SphereConfig | None = None,
                segments: SegmentConfig | None = None, noise_mm: float | None = None,
                video: VideoConfig | None = None) -> Sample:
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
    hole_model : str
        One of :data:`colonbench.datagen.holes.HOLE_MODELS`.
    noise_mm : float, optional
        Gaussian noise sigma on the partial points (default: ``segments.noise_mm``).
    video : VideoConfig, optional
        The ``video`` hole model's settings.
    """
    camera = camera or CameraConfig()
    spheres = spheres or SphereConfig()
    segments = segments or SegmentConfig()
    noise = segments.noise_mm if noise_mm is None else float(noise_mm)
    mesh = surface.mesh
    areas = mesh.area_faces
    if hole_model == "video":  # the partial points are drawn on the fused surface
        observed, coverage, partial, info = _video_covered(rng, scene, centerline, surface, camera, segments,
                                                           video or VideoConfig())
    else:
        observed, coverage, info = observe_covered(rng, scene, centerline, surface, hole_model, camera, spheres,
                                                   segments.min_coverage, segments)
        if _realistic(segments):
            # the reconstruction's flaws draw from a stream of their own, split off only when one is set, so
            # that a config without them gives the samples it gave before they existed
            partial, info["cloud"] = reconstruction_cloud(np.random.default_rng(rng.integers(2**63)), mesh,
                                                          observed, surface, segments, info)
        else:
            partial = sample_surface(rng, mesh.vertices, mesh.faces[observed], segments.point_density,
                                     areas=areas[observed])
    holes = sample_surface(rng, mesh.vertices, mesh.faces[~observed], segments.hole_point_density,
                           areas=areas[~observed])
    if noise > 0:
        partial = partial + rng.normal(0.0, noise, partial.shape)
    return Sample(mesh, observed, surface.centerline, coverage, partial, holes, hole_areas(mesh, observed),
                  surface.window, hole_model, noise, info)
