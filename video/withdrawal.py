"""A rendered colonoscopy: the camera model, a withdrawal trajectory and what each frame sees.

Conventions (the frame dataset of :mod:`colonbench.video.framedata` keeps them)
-------------------------------------------------------------------------------
- Units: millimetres and seconds; the world frame is the colon mesh's frame.
- Camera axes as in OpenCV: x to the right of the image, y down, z forward
  (the viewing direction); right-handed.
- A pose is camera-to-world: ``X_world = R @ X_cam + t``, as a 4 x 4 matrix.
- Pinhole intrinsics ``fx, fy, cx, cy`` in pixels, pixel centres at integer
  coordinates (the top-left pixel's centre is (0, 0)); a camera point
  ``(x, y, z)`` lands on pixel ``u = fx x / z + cx`` (column), ``v = fy y / z + cy``
  (row). The field of view is given on the image diagonal (a colonoscope's
  140 degrees), the principal point is the image centre.
- Depth is the z coordinate of the surface point in the camera frame (not the
  distance along the ray), 0 where the ray meets nothing.

Frames are found by ray casting in Embree (:class:`~colonbench.datagen.camera.SurfaceScene`):
depth and the face under each pixel are exact for the mesh. A face is *seen*
by a frame when its centroid projects inside the image, lies between
``near_mm`` and ``reach_mm`` from the camera, is seen at an incidence of at most
``max_incidence_deg`` (90 by default: any), and the ray to it meets no other
surface first: the rule of the ``camera`` hole model, with the pinhole's
rectangular field of view instead of a cone. The colour image comes from
:mod:`colonbench.video.mucosa` (pyrender).

The trajectory is a withdrawal from the caecum (arc length 0) towards the
rectum at a drawn speed, pushed back in now and then, looking up the colon
(towards the caecum, as the tip of a withdrawn scope does) and around it, the
tip wandering off the centerline and turning about its axis (torque).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from colonbench.datagen.config import VideoConfig
from colonbench.params import draw


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics (pixels; OpenCV convention, see the module's description)."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    @classmethod
    def wide(cls, width: int, height: int | None = None, fov_deg: float = 140.0) -> "Intrinsics":
        """Square pixels, principal point at the centre, ``fov_deg`` across the image diagonal."""
        height = width if height is None else height
        if not 0 < fov_deg < 180:
            raise ValueError(f"the field of view must be in (0, 180) degrees, got {fov_deg}")
        f = 0.5 * np.hypot(width, height) / np.tan(np.radians(fov_deg) / 2)
        return cls(int(width), int(height), float(f), float(f), (width - 1) / 2.0, (height - 1) / 2.0)

    def matrix(self) -> np.ndarray:
        """The 3 x 3 camera matrix K."""
        return np.array([[self.fx, 0, self.cx], [0, self.fy, self.cy], [0, 0, 1.0]])

    def rays(self) -> np.ndarray:
        """(height * width, 3) camera-frame directions with z = 1, row by row (pixel (u, v) at ``v * width + u``)."""
        v, u = np.mgrid[0:self.height, 0:self.width]
        return np.stack([(u.ravel() - self.cx) / self.fx, (v.ravel() - self.cy) / self.fy,
                         np.ones(u.size)], axis=1)

    def project(self, points_cam) -> np.ndarray:
        """(k, 2) pixel coordinates (u, v) of (k, 3) camera-frame points."""
        p = np.asarray(points_cam, float)
        return np.stack([self.fx * p[:, 0] / p[:, 2] + self.cx, self.fy * p[:, 1] / p[:, 2] + self.cy], axis=1)

    def to_dict(self) -> dict:
        return {"width": self.width, "height": self.height, "fx": self.fx, "fy": self.fy, "cx": self.cx,
                "cy": self.cy}


@dataclass
class Trajectory:
    """Camera poses in time order.

    Attributes
    ----------
    times : (k,) float, s
    poses : (k, 4, 4) float
        Camera-to-world, OpenCV camera axes, mm.
    arclength : (k,) float
        Arc length of the centerline point each pose was placed at, mm.
    """

    times: np.ndarray
    poses: np.ndarray
    arclength: np.ndarray

    def __len__(self):
        return len(self.times)

    @property
    def positions(self) -> np.ndarray:
        """(k, 3) camera centres, mm."""
        return self.poses[:, :3, 3]

    def speeds(self) -> tuple[np.ndarray, np.ndarray]:
        """Linear (mm/s) and angular (degree/s) speed at each pose, from its neighbours; (k,) each."""
        if len(self) < 2:
            return np.zeros(len(self)), np.zeros(len(self))
        dt = np.maximum(np.diff(self.times), 1e-9)
        lin = np.linalg.norm(np.diff(self.positions, axis=0), axis=1) / dt
        rel = np.einsum("kji,kjl->kil", self.poses[:-1, :3, :3], self.poses[1:, :3, :3])
        cos = np.clip((np.trace(rel, axis1=1, axis2=2) - 1) / 2, -1.0, 1.0)
        ang = np.degrees(np.arccos(cos)) / dt

        def at_poses(x):  # a pose's speed: the faster of the steps into and out of it
            return np.maximum(np.concatenate([x[:1], x]), np.concatenate([x, x[-1:]]))

        return at_poses(lin), at_poses(ang)


def _smooth(rng, t, period) -> np.ndarray:
    """A smooth random signal in [-1, 1]: three sinusoids, the slowest of the given period (s)."""
    out = np.zeros_like(t)
    amps = np.array([1.0, 0.5, 0.25])
    for a, p in zip(amps, period / np.array([1.0, 2.3, 4.1])):
        out += a * np.sin(2 * np.pi * t / p + rng.uniform(0, 2 * np.pi))
    return out / amps.sum()


def withdrawal_arclength(rng, s_start: float, s_end: float, config: VideoConfig, fps: float,
                         length_mm: float | None = None) -> np.ndarray:
    """Arc lengths of the tip at each frame, withdrawing from ``s_start`` to ``s_end`` (mm).

    The speed is drawn from ``config.speed_mm_s``; after each mm of withdrawal
    the scope is pushed back in by a drawn ``push_back_mm`` with probability
    ``push_back_per_100mm / 100`` (never before arc length 0).
    """
    v = draw(rng, config.speed_mm_s)
    step = v / fps
    rate = config.push_back_per_100mm / 100.0
    s, out = float(s_start), [float(s_start)]
    while s < s_end:
        if rng.random() < rate * step:
            back = draw(rng, config.push_back_mm)
            n = max(int(np.ceil(back / step)), 1)
            out.extend(max(s - step * i, 0.0) for i in range(1, n + 1))
            out.extend(max(s - step * i, 0.0) for i in range(n - 1, 0, -1))
        s = min(s + step, s_end)
        out.append(s)
    out = np.asarray(out)
    return np.clip(out, 0.0, length_mm) if length_mm is not None else out


def withdrawal(rng, scene, centerline, s_start: float, s_end: float, config: VideoConfig,
               fps: float | None = None) -> Trajectory:
    """A withdrawal trajectory between two arc lengths (see the module's description).

    Parameters
    ----------
    rng : numpy.random.Generator
    scene : SurfaceScene
        The colon (to keep the tip inside the lumen).
    centerline : Centerline
        Arc length 0 at the caecum.
    s_start, s_end : float
        Arc lengths where the withdrawal starts and ends, mm (``s_start < s_end``).
    config : VideoConfig
    fps : float, optional
        Frames per second (default ``config.fps``).

    Returns
    -------
    Trajectory
    """
    fps = float(config.fps if fps is None else fps)
    s = withdrawal_arclength(rng, s_start, s_end, config, fps, centerline.length)
    t = np.arange(len(s)) / fps
    period = draw(rng, config.look_period_s)
    tilt_max = np.radians(draw(rng, config.look_around_deg))
    yaw, pitch = tilt_max * _smooth(rng, t, period), tilt_max * _smooth(rng, t, period)
    roll = np.radians(30.0) * _smooth(rng, t, 2 * period)
    lo, hi = config.lateral_offset
    frac = lo + (hi - lo) * 0.5 * (1 + _smooth(rng, t, period))
    phi = np.pi * _smooth(rng, t, 1.5 * period)

    _, normal_s, _ = centerline.frames()
    centre = centerline.point_at(s)
    tangent = centerline.tangent_at(s)
    normal = np.stack([np.interp(s, centerline.arclength, normal_s[:, k]) for k in range(3)], axis=1)
    normal -= np.sum(normal * tangent, axis=1, keepdims=True) * tangent
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    binormal = np.cross(tangent, normal)

    side = np.cos(phi)[:, None] * normal + np.sin(phi)[:, None] * binormal
    wall, _ = scene.cast(centre, side)
    wall = np.where(np.isfinite(wall), wall, scene.distance(centre))
    position = centre + (frac * wall)[:, None] * side

    forward = -tangent  # the tip of a withdrawn scope looks up the colon, towards the caecum
    a = np.minimum(np.hypot(yaw, pitch), tilt_max)
    psi = np.arctan2(pitch, yaw)
    z = np.cos(a)[:, None] * forward + np.sin(a)[:, None] * (np.cos(psi)[:, None] * normal
                                                             + np.sin(psi)[:, None] * binormal)
    z /= np.linalg.norm(z, axis=1, keepdims=True)
    x0 = normal - np.sum(normal * z, axis=1, keepdims=True) * z
    x0 /= np.linalg.norm(x0, axis=1, keepdims=True)
    y0 = np.cross(z, x0)
    x = np.cos(roll)[:, None] * x0 + np.sin(roll)[:, None] * y0
    y = np.cross(z, x)
    poses = np.tile(np.eye(4), (len(s), 1, 1))
    poses[:, :3, 0], poses[:, :3, 1], poses[:, :3, 2], poses[:, :3, 3] = x, y, z, position
    return Trajectory(t, poses, s)


class FrameCaster:
    """Depth, face ids and seen faces of frames of one mesh, by Embree ray casting.

    Parameters
    ----------
    scene : SurfaceScene
    intrinsics : Intrinsics
    near_mm, reach_mm : float
        Faces are seen between these distances from the camera (mm).
    max_incidence_deg : float
        Faces are seen when the angle between the line of sight and their
        normal is at most this (90: any angle).
    """

    def __init__(self, scene, intrinsics: Intrinsics, near_mm: float = 2.0, reach_mm: float = 100.0,
                 max_incidence_deg: float = 90.0):
        self.scene = scene
        self.intrinsics = intrinsics
        self.near_mm = float(near_mm)
        self.reach_mm = float(reach_mm)
        self.min_cos = float(np.cos(np.radians(max_incidence_deg))) if max_incidence_deg < 90 else -1.0
        tri = scene.vertices[scene.faces]
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        self._normals = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
        self._rays = intrinsics.rays()
        self._norm = np.linalg.norm(self._rays, axis=1)
        self._tree = None  # of the face centroids, built on first use

    def depth(self, pose, max_distance: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Depth and the face under each pixel at a pose; (height, width) each.

        Returns
        -------
        depth : (height, width) float32
            z in the camera frame, mm; 0 where the ray meets nothing (or meets
            the surface farther than ``max_distance`` mm from the camera, or
            at more than the caster's largest incidence angle).
        face : (height, width) int32
            Index of the face hit, -1 where none.
        """
        pose = np.asarray(pose, float)
        dirs = (self._rays / self._norm[:, None]) @ pose[:3, :3].T
        t, face = self.scene.cast(np.broadcast_to(pose[:3, 3], dirs.shape), dirs)
        hit = np.isfinite(t) if max_distance is None else np.isfinite(t) & (t <= max_distance)
        if self.min_cos > -1.0:
            hit &= np.abs(np.sum(self._normals[np.maximum(face, 0)] * dirs, axis=1)) >= self.min_cos
        z = np.where(hit, t / self._norm, 0.0)
        shape = (self.intrinsics.height, self.intrinsics.width)
        return z.reshape(shape).astype(np.float32), face.reshape(shape).astype(np.int32)

    def seen(self, pose, candidates: np.ndarray | None = None, reach_mm: float | None = None) -> np.ndarray:
        """Indices of the faces the frame sees (see the module's description); sorted (k,) int.

        ``candidates`` (face indices) restricts the test to those faces;
        ``reach_mm`` replaces the caster's reach for this frame.
        """
        pose = np.asarray(pose, float)
        reach = self.reach_mm if reach_mm is None else float(reach_mm)
        if candidates is None:
            if self._tree is None:
                self._tree = cKDTree(self.scene.centroids)
            idx = np.asarray(self._tree.query_ball_point(pose[:3, 3], reach), dtype=np.int64)
        else:
            idx = np.asarray(candidates, dtype=np.int64)
            idx = idx[np.sum((self.scene.centroids[idx] - pose[:3, 3]) ** 2, axis=1) <= reach ** 2]
        if len(idx) == 0:
            return idx
        rel = self.scene.centroids[idx] - pose[:3, 3]
        cam = rel @ pose[:3, :3]
        dist = np.linalg.norm(rel, axis=1)
        ok = (cam[:, 2] > 1e-6) & (dist >= self.near_mm) & (dist <= reach)
        if self.min_cos > -1.0:
            ok &= np.abs(np.sum(self._normals[idx] * rel, axis=1)) >= self.min_cos * dist
        uv = self.intrinsics.project(cam[ok])
        inside = ((uv[:, 0] >= -0.5) & (uv[:, 0] <= self.intrinsics.width - 0.5)
                  & (uv[:, 1] >= -0.5) & (uv[:, 1] <= self.intrinsics.height - 0.5))
        cand = np.flatnonzero(ok)[inside]
        if len(cand) == 0:
            return cand
        unit = rel[cand] / dist[cand, None]
        t, _ = self.scene.cast(np.broadcast_to(pose[:3, 3], unit.shape), unit)
        visible = t >= dist[cand] - (1e-4 * dist[cand] + 1e-3)
        return np.sort(idx[cand[visible]])


def pose_to_tum(time_s: float, pose) -> str:
    """One line of a TUM trajectory: ``time tx ty tz qx qy qz qw`` (camera-to-world, mm)."""
    from scipy.spatial.transform import Rotation

    pose = np.asarray(pose, float)
    q = Rotation.from_matrix(pose[:3, :3]).as_quat()  # x, y, z, w
    t = pose[:3, 3]
    return (f"{time_s:.6f} {t[0]:.6f} {t[1]:.6f} {t[2]:.6f} "
            f"{q[0]:.9f} {q[1]:.9f} {q[2]:.9f} {q[3]:.9f}")


def tum_to_poses(lines) -> tuple[np.ndarray, np.ndarray]:
    """Times (k,) and camera-to-world poses (k, 4, 4) from TUM lines (``#`` comments skipped)."""
    from scipy.spatial.transform import Rotation

    rows = [np.array(line.split(), float) for line in lines if line.strip() and not line.lstrip().startswith("#")]
    rows = np.array(rows).reshape(-1, 8)
    poses = np.tile(np.eye(4), (len(rows), 1, 1))
    poses[:, :3, :3] = Rotation.from_quat(rows[:, 4:8]).as_matrix()
    poses[:, :3, 3] = rows[:, 1:4]
    return rows[:, 0], poses
