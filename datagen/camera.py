"""A virtual colonoscope: random poses inside the lumen and what they see, by Embree ray casting.

Model
-----
- A pose is a position and a unit view direction. The field of view is a
  circular cone of full angle ``fov_deg`` (a colonoscope's wide-angle image is
  nearly circular), so the roll about the view axis does not change what is
  seen and is not drawn.
- A face is *seen* by a pose when its centroid lies inside the cone, between
  ``near_mm`` and the pose's reach, and the ray from the camera to the centroid
  meets no other surface first (Embree through open3d's ``RaycastingScene``;
  occlusion by haustral folds and by other loops of the colon is exact).
  Faces are at most about 1 mm across, so deciding per face at its centroid is
  exact to the mesh resolution.
- A permutation's observed surface is the union of what its poses see.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from colonbench.datagen.config import CameraConfig
from colonbench.params import draw
from colonbench.polyline import perpendicular_basis


class SurfaceScene:
    """A triangle mesh loaded once into Embree, with per-face centroids and areas.

    Parameters
    ----------
    vertices : (n, 3) float, mm
    faces : (m, 3) int
    """

    def __init__(self, vertices, faces):
        import open3d as o3d

        self.vertices = np.asarray(vertices, dtype=np.float64)
        self.faces = np.asarray(faces, dtype=np.int64)
        tri = self.vertices[self.faces]
        self.centroids = tri.mean(axis=1)
        cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        self.areas = 0.5 * np.linalg.norm(cross, axis=1)
        self._scene = o3d.t.geometry.RaycastingScene()
        self._scene.add_triangles(o3d.core.Tensor(self.vertices.astype(np.float32)),
                                  o3d.core.Tensor(self.faces.astype(np.uint32)))

    def cast(self, origins, directions):
        """First hits of rays.

        Parameters
        ----------
        origins, directions : (k, 3) float
            Ray origins (mm) and unit directions.

        Returns
        -------
        t_hit : (k,) float
            Distance to the first hit, mm (``inf`` when none).
        face : (k,) int
            Index of the face hit, -1 when none.
        """
        import open3d as o3d

        rays = np.concatenate([origins, directions], axis=1).astype(np.float32)
        ans = self._scene.cast_rays(o3d.core.Tensor(rays))
        t = ans["t_hit"].numpy().astype(np.float64)
        face = ans["primitive_ids"].numpy().astype(np.int64)
        face[~np.isfinite(t)] = -1
        return t, face

    def distance(self, points):
        """Unsigned distance (mm) from (k, 3) points to the surface."""
        import open3d as o3d

        q = o3d.core.Tensor(np.asarray(points, dtype=np.float32).reshape(-1, 3))
        return self._scene.compute_distance(q).numpy().astype(np.float64)

    def occupancy(self, points, nsamples: int = 9):
        """Whether (k, 3) points lie inside the surface (majority of ray parities); (k,) bool."""
        import open3d as o3d

        q = o3d.core.Tensor(np.asarray(points, dtype=np.float32).reshape(-1, 3))
        return self._scene.compute_occupancy(q, nsamples=nsamples).numpy() > 0.5


@dataclass
class Poses:
    """Camera poses.

    Attributes
    ----------
    positions : (p, 3) float, mm
    directions : (p, 3) float, unit view directions
    reach_mm : (p,) float, farthest distance seen by each pose
    arclength : (p,) float, arc length of the centerline point each pose was placed at, mm
    """

    positions: np.ndarray
    directions: np.ndarray
    reach_mm: np.ndarray
    arclength: np.ndarray

    def __len__(self):
        return len(self.positions)


def sample_poses(rng: np.random.Generator, scene: SurfaceScene, centerline, s_range, config: CameraConfig,
                 n_poses: int | None = None) -> Poses:
    """Draw camera poses near a stretch of the centerline.

    Parameters
    ----------
    rng : numpy.random.Generator
    scene : SurfaceScene
        The whole colon (used to keep the camera away from the wall).
    centerline : Centerline
    s_range : (float, float)
        Arc-length window, mm; poses are placed in it, widened by
        ``config.spread_mm`` on both sides and clipped to the colon.
    config : CameraConfig
    n_poses : int, optional
        Number of poses (default: drawn from ``config.poses``).

    Returns
    -------
    Poses
        Each pose sits at a centerline point, moved sideways by a drawn fraction
        of the distance to the nearest wall, looking along the tangent (or
        against it, with probability ``backward_fraction``) tilted by up to
        ``cone_deg`` (uniform on the spherical cap).
    """
    n = int(n_poses if n_poses is not None else draw(rng, config.poses, integer=True))
    lo = max(0.0, s_range[0] - config.spread_mm)
    hi = min(centerline.length, s_range[1] + config.spread_mm)
    s = rng.uniform(lo, hi, n)
    center = centerline.point_at(s)
    tangent = centerline.tangent_at(s)
    u, v = perpendicular_basis(tangent)
    phi = rng.uniform(0, 2 * np.pi, n)
    side = np.cos(phi)[:, None] * u + np.sin(phi)[:, None] * v
    frac = rng.uniform(config.lateral_offset[0], config.lateral_offset[1], n)
    # distance to the wall along the sideways direction
    wall, _ = scene.cast(center, side)
    wall = np.where(np.isfinite(wall), wall, scene.distance(center))
    position = center + (frac * wall)[:, None] * side

    backward = rng.random(n) < config.backward_fraction
    axis = np.where(backward[:, None], -tangent, tangent)
    cos_max = np.cos(np.radians(config.cone_deg))
    cos_a = rng.uniform(cos_max, 1.0, n)
    sin_a = np.sqrt(1 - cos_a**2)
    psi = rng.uniform(0, 2 * np.pi, n)
    au, av = perpendicular_basis(axis)
    direction = cos_a[:, None] * axis + sin_a[:, None] * (np.cos(psi)[:, None] * au + np.sin(psi)[:, None] * av)
    reach = rng.uniform(config.reach_mm[0], config.reach_mm[1], n)
    return Poses(position, direction, reach, s)


def visible_faces(scene: SurfaceScene, poses: Poses, fov_deg: float, near_mm: float = 0.0,
                  candidates: np.ndarray | None = None, margins: bool = False):
    """Faces seen by at least one pose.

    A face is seen from a pose when its centroid is inside the view cone, between ``near_mm`` and the pose's
    reach, and the ray to it hits nothing more than a hair (``1e-4`` of the distance + ``1e-3`` mm) before it.

    Parameters
    ----------
    scene : SurfaceScene
    poses : Poses
    fov_deg : float
        Full angle of the field-of-view cone, degrees.
    near_mm : float
        Closest distance seen, mm.
    candidates : (k,) int, optional
        Only these faces are tested (others are reported unseen).
    margins : bool
        Also return how near a tie each face's decision was.

    Returns
    -------
    seen : (m,) bool
        One flag per face of the scene.
    margin : (m,) float
        Only with ``margins``: per face, the smallest |hit distance - the distance a hit must reach to count as
        the face|, mm, over the poses whose ray tested it (inf for faces no ray tested): the faces with the
        smallest margins are those another CPU's float rounding can flip.
    """
    seen = np.zeros(len(scene.faces), dtype=bool)
    margin = np.full(len(scene.faces), np.inf)
    idx = np.arange(len(scene.faces)) if candidates is None else np.asarray(candidates)
    cents = scene.centroids[idx]
    cos_half = np.cos(np.radians(fov_deg) / 2.0)
    for p in range(len(poses)):
        d = cents - poses.positions[p]
        dist = np.linalg.norm(d, axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            unit = d / dist[:, None]
        ok = (dist <= poses.reach_mm[p]) & (dist >= near_mm) & (unit @ poses.directions[p] >= cos_half)
        ok &= ~seen[idx]
        if not ok.any():
            continue
        t, _ = scene.cast(np.broadcast_to(poses.positions[p], (int(ok.sum()), 3)), unit[ok])
        tol = 1e-4 * dist[ok] + 1e-3
        seen[idx[ok]] = t >= dist[ok] - tol
        if margins:
            margin[idx[ok]] = np.minimum(margin[idx[ok]], np.abs(t - (dist[ok] - tol)))
    return (seen, margin) if margins else seen
