"""A whole colon's partial reconstruction and its withdrawal trajectory (the map's demo and benchmark input).

The camera positions follow the centerline from the caecum to the rectum (a
withdrawal), with the back-and-forth of a real examination, drifting off the
centerline as a SLAM trajectory does (:func:`trajectory`). Two hole models:

- ``spheres`` (the paper's for CT colons): spheres centred on the surface crop
  the wall; a face is observed when its centroid is outside every sphere.
- ``camera``: what the withdrawing colonoscope sees (``datagen.camera``:
  exact per-face visibility by ray casting), from every 10 mm of the path,
  looking up the colon towards the caecum, tilted by up to 60 degrees (looking
  around), off the centerline by up to half the way to the wall. The far sides
  of folds facing the rectum are missed, as in a real withdrawal.

Either way the per-face observed mask is the exact ground truth, and the
partial cloud is drawn on the observed faces only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from colonbench import seeding
from colonbench.datagen.config import WholeConfig
from colonbench.datagen.holes import inside_spheres
from colonbench.meshes import sample_surface


@dataclass
class WholePartial:
    """A whole colon's partial reconstruction (mm).

    Attributes
    ----------
    points : (n, 3) float
        The partial cloud.
    positions : (k, 3) float
        Camera positions in time order, caecum to rectum.
    observed : (f,) bool
        Per face of the colon's mesh: its centroid is outside every hole sphere.
    spheres : (h, 4) float
        Hole spheres: centre x, y, z and radius, mm.
    """

    points: np.ndarray
    positions: np.ndarray
    observed: np.ndarray
    spheres: np.ndarray


def withdrawal(colon, seed: int) -> np.ndarray:
    """Camera positions from the caecum to the rectum at 2 mm a pose, going back 10-30 mm now and then."""
    rng = seeding.rng(seed, "whole", "trajectory")
    s, path, length = 0.0, [], colon.centerline.length
    while s < length:
        path.append(s)
        s += 2.0
        if rng.random() < 0.02:
            back = rng.uniform(10.0, 30.0)
            path.extend(np.arange(s, max(s - back, 0.0), -2.0))
    return np.clip(np.array(path), 0.0, length)


def trajectory(colon, seed: int, config: WholeConfig | None = None, scene=None) -> np.ndarray:
    """(k, 3) recorded camera positions, mm: the withdrawal (:func:`withdrawal`), drifting off the centerline.

    A SLAM trajectory is not the colon's centerline: the scope wanders off it,
    towards a wall in the bends. At knots ``config.trajectory_drift_mm`` apart
    along the centerline a vector is drawn uniformly in the ball of radius
    ``config.trajectory_offset``; between knots it is interpolated linearly,
    and its part across the centerline's tangent is the position's offset as
    a share of the distance to the wall in that direction. Positions at the
    same arc length (a pull-back) coincide. ``trajectory_offset`` 0 gives the
    centerline itself. ``scene``: the colon mesh's
    :class:`~colonbench.datagen.camera.SurfaceScene`, when the caller has one.
    """
    config = config or WholeConfig()
    line = colon.centerline
    s = withdrawal(colon, seed)
    centre = line.point_at(s)
    if config.trajectory_offset <= 0:
        return centre
    from colonbench.datagen.camera import SurfaceScene

    rng = seeding.rng(seed, "whole", "trajectory-drift")
    knots = np.arange(0.0, line.length + config.trajectory_drift_mm, config.trajectory_drift_mm)
    w = rng.normal(size=(len(knots), 3))
    w *= (config.trajectory_offset * rng.random(len(knots)) ** (1 / 3) / np.linalg.norm(w, axis=1))[:, None]
    w = np.stack([np.interp(s, knots, w[:, i]) for i in range(3)], axis=1)
    tangent = line.tangent_at(s)
    side = w - np.sum(w * tangent, axis=1, keepdims=True) * tangent
    share = np.linalg.norm(side, axis=1)
    direction = side / np.maximum(share, 1e-12)[:, None]
    scene = scene or SurfaceScene(colon.mesh.vertices, colon.mesh.faces)
    wall, _ = scene.cast(centre, direction)
    wall = np.where(np.isfinite(wall), wall, scene.distance(centre))
    return centre + (share * wall)[:, None] * direction


def camera_observed(colon, seed: int, config: WholeConfig | None = None, scene=None) -> np.ndarray:
    """(f,) bool: faces a withdrawing colonoscope sees (see the module's description).

    The views are ``config.camera_step_mm`` apart along the centerline; each
    looks up the colon tilted by up to ``camera_tilt_deg``, sits off the
    centerline by up to ``camera_offset`` of the way to the wall, and sees
    ``camera_reach_mm`` far with a ``fov_deg`` field of view. ``scene``: the
    colon mesh's :class:`~colonbench.datagen.camera.SurfaceScene`, when the
    caller has one.
    """
    from colonbench.datagen.camera import Poses, SurfaceScene, visible_faces
    from colonbench.polyline import perpendicular_basis

    config = config or WholeConfig()
    rng = seeding.rng(seed, "whole", "camera")
    line = colon.centerline
    scene = scene or SurfaceScene(colon.mesh.vertices, colon.mesh.faces)
    s = np.arange(0.0, line.length, config.camera_step_mm)
    centre, tangent = line.point_at(s), line.tangent_at(s)
    u, v = perpendicular_basis(tangent)
    phi = rng.uniform(0, 2 * np.pi, len(s))
    side = np.cos(phi)[:, None] * u + np.sin(phi)[:, None] * v
    wall, _ = scene.cast(centre, side)
    wall = np.where(np.isfinite(wall), wall, scene.distance(centre))
    position = centre + (rng.uniform(0, config.camera_offset, len(s)) * wall)[:, None] * side
    axis = -tangent  # looking up the colon, towards the caecum
    cos_a = rng.uniform(np.cos(np.radians(config.camera_tilt_deg)), 1.0, len(s))
    psi = rng.uniform(0, 2 * np.pi, len(s))
    au, av = perpendicular_basis(axis)
    direction = cos_a[:, None] * axis + np.sqrt(1 - cos_a**2)[:, None] * (
        np.cos(psi)[:, None] * au + np.sin(psi)[:, None] * av)
    reach = rng.uniform(config.camera_reach_mm[0], config.camera_reach_mm[1], len(s))
    return visible_faces(scene, Poses(position, direction, reach, s), config.fov_deg, near_mm=2.0)


#: The whole-colon hole models.
WHOLE_HOLE_MODELS = ("spheres", "camera")


def whole_partial(colon, seed: int = 0, holes: str = "spheres", config: WholeConfig | None = None) -> WholePartial:
    """Partial cloud of a whole colon, with a withdrawal trajectory.

    Parameters
    ----------
    colon : colonbench.datagen.colon.Colon
        Its centerline runs from the caecum (arc length 0) to the anus.
    seed : int
        Root seed; the draws descend from it (``seeding.rng(seed, "whole", ...)``).
    holes : str
        ``"spheres"`` or ``"camera"`` (see the module's description).
    config : colonbench.datagen.config.WholeConfig, optional
        Density and hole settings (its defaults when omitted).
    """
    from colonbench.errors import InputError

    config = config or WholeConfig()
    v, f = np.asarray(colon.mesh.vertices), np.asarray(colon.mesh.faces)
    scene = None  # the ray-casting scene, built once for the trajectory and the camera's views
    if config.trajectory_offset > 0 or holes == "camera":
        from colonbench.datagen.camera import SurfaceScene

        scene = SurfaceScene(v, f)
    positions = trajectory(colon, seed, config, scene)
    if holes == "spheres":
        rng = seeding.rng(seed, "whole", "holes")
        count = max(int(round(config.holes_per_m * colon.centerline.length / 1000.0)), 1)
        centres = sample_surface(rng, v, f, count=count)
        radii = rng.uniform(config.sphere_radius_mm[0], config.sphere_radius_mm[1], count)
        observed = ~inside_spheres(v[f].mean(axis=1), centres, radii)
        spheres = np.concatenate([centres, radii[:, None]], axis=1)
    elif holes == "camera":
        observed = camera_observed(colon, seed, config, scene)
        spheres = np.zeros((0, 4))
    else:
        raise InputError(f"unknown whole-colon hole model {holes!r}; use one of {list(WHOLE_HOLE_MODELS)}")
    pts = sample_surface(seeding.rng(seed, "whole", "points"), v, f[observed], density=config.point_density)
    return WholePartial(points=pts, positions=positions, observed=observed, spheres=spheres)
