"""Reconstruction-like partials: rendered depth, degraded as real pipelines degrade it, fused by TSDF.

This is the ``video`` hole model. For one segment:

1. a withdrawal through the segment and ``camera.spread_mm`` beyond both ends
   is rendered as depth frames (:mod:`colonbench.video.withdrawal`);
2. frames taken while the tip moves faster than ``skip_mm_s`` or turns faster
   than ``skip_deg_s`` are dropped (motion blur makes them useless), and so are
   those of tracking losses: a Poisson number of them
   (``tracking_loss_per_100mm`` per 100 mm of the path's arc length), each
   ``tracking_loss_s`` long, at uniform times;
3. each kept depth frame is degraded:

   - edge smoothing: a Gaussian of ``edge_blur_px`` over the valid pixels
     (normalised convolution), which rounds fold edges and spreads depth across
     occluding contours as monocular depth networks do;
   - depth noise: Gaussian, sigma ``depth_noise`` times the depth;
   - scale drift: depth multiplied by ``exp(lambda_k)``;

4. the poses drift (:func:`draw_drift`, :func:`apply_drift`): the pipeline's
   relative motion between consecutive frames is wrong by a small rotation and
   translation in the camera frame, and its translation scaled by
   ``exp(lambda_k)``; ``lambda`` and the errors are random walks of
   ``drift_scale``, ``drift_rot_deg`` and ``drift_trans_mm`` per square root of a
   second. The drift is anchored at the frame nearest the segment's middle
   (that frame's pose is exact), so the reconstruction is registered to the
   truth where it matters, and bends and doubles away from it;
5. the kept frames are fused in open3d's TSDF (``VoxelBlockGrid``, voxel
   ``voxel_mm``, truncation ``trunc_mm``; only what lies within the drawn
   ``reach_mm`` of the camera, and seen at no more than ``max_incidence_deg``
   from the surface normal, where depth is usable) and its surface extracted
   (marching cubes);
6. the fused surface is cut to the segment (between its two planes, and
   nearest to its stretch of the centerline) and sampled at the segment
   config's ``point_density``: the partial points.

The ground truth stays exact: a face of the segment is observed when a kept
frame sees it (:meth:`colonbench.video.withdrawal.FrameCaster.seen`), whatever the
degradation did to the fused surface.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from colonbench.datagen.config import VideoConfig
from colonbench.errors import InputError
from colonbench.params import draw


def smooth_depth(depth, sigma_px: float) -> np.ndarray:
    """Gaussian smoothing of a depth image over its valid (non-zero) pixels; (h, w) float32.

    Invalid pixels stay 0; valid ones near an edge take a weighted mean of their
    valid neighbours (normalised convolution).
    """
    from scipy.ndimage import gaussian_filter

    depth = np.asarray(depth, np.float64)
    if sigma_px <= 0:
        return depth.astype(np.float32)
    valid = (depth > 0).astype(np.float64)
    num = gaussian_filter(depth * valid, sigma_px, mode="nearest")
    den = gaussian_filter(valid, sigma_px, mode="nearest")
    out = np.where(valid > 0, num / np.maximum(den, 1e-12), 0.0)
    return out.astype(np.float32)


def degrade_depth(rng, depth, noise: float, blur_px: float, log_scale: float = 0.0) -> np.ndarray:
    """Depth as a real pipeline gives it: smoothed over edges, scaled by ``exp(log_scale)``, noisy ``noise * z``."""
    d = smooth_depth(depth, blur_px).astype(np.float64) * np.exp(log_scale)
    if noise > 0:
        d = d + rng.normal(size=d.shape) * noise * d
    return np.where(np.asarray(depth) > 0, np.maximum(d, 0.0), 0.0).astype(np.float32)


def draw_drift(rng, times, anchor: int, rot_deg: float, trans_mm: float, scale: float) -> dict:
    """Per-step errors of a drifting pipeline: random walks per square root of a second.

    Parameters
    ----------
    rng : numpy.random.Generator
    times : (k,) float, s
    anchor : int
        The frame whose pose is exact.
    rot_deg, trans_mm, scale : float
        Standard deviations per sqrt(s) of the rotation error (degrees), the
        translation error (mm, camera frame) and the log-scale walk.

    Returns
    -------
    dict
        ``rotvec`` (k, 3) rad and ``trans`` (k, 3) mm: the error of the step
        from frame k-1 to k (row 0 unused); ``log_scale`` (k,): the scale walk,
        0 at the anchor.
    """
    times = np.asarray(times, float)
    k = len(times)
    dt = np.concatenate([[0.0], np.diff(times)])
    sq = np.sqrt(np.maximum(dt, 0.0))[:, None]
    rotvec = rng.normal(size=(k, 3)) * np.radians(rot_deg) * sq
    trans = rng.normal(size=(k, 3)) * trans_mm * sq
    steps = rng.normal(size=k) * scale * sq[:, 0]
    walk = np.cumsum(steps)
    return {"rotvec": rotvec, "trans": trans, "log_scale": walk - walk[anchor]}


def apply_drift(poses, drift: dict, anchor: int) -> np.ndarray:
    """The poses a drifting pipeline estimates; (k, 4, 4).

    From the anchor outwards, each relative motion between consecutive true
    poses has its translation scaled by ``exp(log_scale)`` of the later frame
    and is followed by that step's error (rotation vector, translation in the
    camera frame).
    """
    poses = np.asarray(poses, float)
    k = len(poses)
    if not 0 <= anchor < k:
        raise InputError(f"drift anchor {anchor} is not a frame (0..{k - 1})")
    out = poses.copy()

    def error(i):
        e = np.eye(4)
        e[:3, :3] = Rotation.from_rotvec(drift["rotvec"][i]).as_matrix()
        e[:3, 3] = drift["trans"][i]
        return e

    for i in range(anchor + 1, k):  # forward: step i-1 -> i
        rel = np.linalg.inv(poses[i - 1]) @ poses[i]
        rel[:3, 3] *= np.exp(drift["log_scale"][i])
        out[i] = out[i - 1] @ rel @ error(i)
    for i in range(anchor - 1, -1, -1):  # backward: step i+1 -> i, the inverse of step i -> i+1
        rel = np.linalg.inv(poses[i + 1]) @ poses[i]
        rel[:3, 3] *= np.exp(drift["log_scale"][i])
        out[i] = out[i + 1] @ np.linalg.inv(error(i + 1)) @ rel
    return out


def tsdf_fuse(depths, poses, intrinsics, voxel_mm: float = 1.0, trunc_mm: float = 4.0,
              max_depth_mm: float = 100.0, min_weight: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Fuse depth frames into a surface (open3d's ``VoxelBlockGrid`` TSDF, marching cubes).

    open3d's tensor TSDF is used rather than the legacy ``ScalableTSDFVolume``,
    which finds the blocks a frame touches with depth taken in metres whatever
    the depth scale, and so misses most of a scene in millimetres.

    Parameters
    ----------
    depths : iterable of (h, w) float
        Depth (z, mm), 0 where invalid.
    poses : iterable of (4, 4) float
        Camera-to-world, OpenCV axes, mm.
    intrinsics : Intrinsics
    voxel_mm, trunc_mm : float
        TSDF voxel size and truncation distance, mm.
    max_depth_mm : float
        Depth beyond which pixels are ignored, mm.
    min_weight : int
        Voxels integrated by fewer frames than this are left out of the surface.

    Returns
    -------
    vertices : (n, 3) float, mm
    faces : (m, 3) int
    """
    import open3d as o3d
    import open3d.core as o3c

    cpu = o3c.Device("CPU:0")
    grid = o3d.t.geometry.VoxelBlockGrid(attr_names=("tsdf", "weight"), attr_dtypes=(o3c.float32, o3c.float32),
                                         attr_channels=((1,), (1,)), voxel_size=float(voxel_mm),
                                         block_resolution=16, block_count=50000, device=cpu)
    # open3d takes pixel i to cover [i, i + 1) (it truncates): shift our integer-centred principal point by half
    K = intrinsics.matrix()
    K[:2, 2] += 0.5
    intr = o3c.Tensor(K, o3c.float64)
    mult = float(trunc_mm) / float(voxel_mm)
    for depth, pose in zip(depths, poses):
        image = o3d.t.geometry.Image(o3c.Tensor(np.ascontiguousarray(depth, dtype=np.float32)))
        extr = o3c.Tensor(np.linalg.inv(np.asarray(pose, float)), o3c.float64)
        # positional arguments: open3d 0.19-0.20 resolve keywords here to an overload with colour
        try:
            blocks = grid.compute_unique_block_coordinates(image, intr, extr, 1.0, float(max_depth_mm), mult)
        except RuntimeError:  # open3d refuses a frame whose few valid pixels touch no block: nothing to fuse
            continue
        grid.integrate(blocks, image, intr, extr, 1.0, float(max_depth_mm), mult)
    try:
        mesh = grid.extract_triangle_mesh(weight_threshold=float(min_weight) - 0.5)
    except RuntimeError:  # open3d raises on an empty surface
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    return canonical_mesh(mesh.vertex.positions.numpy().astype(float), mesh.triangle.indices.numpy().astype(np.int64))


def canonical_mesh(vertices, faces) -> tuple[np.ndarray, np.ndarray]:
    """The same triangle mesh in an order fixed by its geometry alone; (n, 3) float, (m, 3) int.

    open3d's TSDF fills its block hash map from several threads, so the order
    of the extracted vertices and triangles changes from run to run while the
    surface does not. Vertices sorted by (x, y, z), each triangle rotated to
    start at its smallest index (its orientation kept), triangles sorted: the
    points sampled on the surface, and the shards, are then the same every run.
    """
    vertices, faces = np.asarray(vertices, float), np.asarray(faces, np.int64)
    if len(faces) == 0:
        return vertices, faces
    order = np.lexsort(vertices.T[::-1])
    rank = np.empty(len(order), np.int64)
    rank[order] = np.arange(len(order))
    f = rank[faces]
    f = np.take_along_axis(f, (np.argmin(f, axis=1)[:, None] + np.arange(3)) % 3, axis=1)
    return vertices[order], f[np.lexsort(f.T[::-1])]


def tracking_lost(rng, trajectory, config: VideoConfig) -> np.ndarray:
    """(k,) bool: the frames of tracking losses (see step 2 of the module's description)."""
    lost = np.zeros(len(trajectory), bool)
    if len(trajectory) == 0:
        return lost
    path = float(np.ptp(trajectory.arclength))
    n = rng.poisson(config.tracking_loss_per_100mm * path / 100.0)
    for _ in range(n):
        start = rng.uniform(trajectory.times[0], trajectory.times[-1])
        lost |= (trajectory.times >= start) & (trajectory.times < start + draw(rng, config.tracking_loss_s))
    return lost


def degradation(rng, config: VideoConfig) -> dict:
    """Draw one sample's degradation settings from the config's ranges (JSON-friendly)."""
    return {"reach_mm": draw(rng, config.reach_mm), "max_incidence_deg": draw(rng, config.max_incidence_deg),
            "depth_noise": draw(rng, config.depth_noise), "edge_blur_px": draw(rng, config.edge_blur_px),
            "drift_rot_deg": draw(rng, config.drift_rot_deg), "drift_trans_mm": draw(rng, config.drift_trans_mm),
            "drift_scale": draw(rng, config.drift_scale)}


def fused_video(rng, caster, trajectory, settings: dict, config: VideoConfig, anchor: int,
                candidates=None) -> dict:
    """Render, degrade and fuse a trajectory's frames (steps 2-5 of the module's description).

    Parameters
    ----------
    rng : numpy.random.Generator
    caster : FrameCaster
        Its reach and largest incidence are the sample's: nothing beyond them is fused or seen.
    trajectory : Trajectory
    settings : dict
        From :func:`degradation`.
    config : VideoConfig
    anchor : int
        Frame whose pose stays exact.
    candidates : (c,) int, optional
        Faces whose visibility is tracked (default: all).

    Returns
    -------
    dict
        ``vertices``, ``faces`` (the fused surface), ``seen`` (sorted face ids seen by a kept frame),
        ``kept`` (k,) bool, ``frames`` (kept count), ``poses`` (the drifted poses).
    """
    lin, ang = trajectory.speeds()
    kept = (lin <= config.skip_mm_s) & (ang <= config.skip_deg_s) & ~tracking_lost(rng, trajectory, config)
    kept[anchor] = True
    drift = draw_drift(rng, trajectory.times, anchor, settings["drift_rot_deg"], settings["drift_trans_mm"],
                       settings["drift_scale"])
    poses = apply_drift(trajectory.poses, drift, anchor)
    depths, seen = [], []
    for i in np.flatnonzero(kept):
        z, _ = caster.depth(trajectory.poses[i], max_distance=caster.reach_mm)
        z[z < config.near_mm] = 0.0
        depths.append(degrade_depth(rng, z, settings["depth_noise"], settings["edge_blur_px"],
                                    drift["log_scale"][i]))
        seen.append(caster.seen(trajectory.poses[i], candidates))
    v, f = tsdf_fuse(depths, poses[kept], caster.intrinsics, config.voxel_mm, config.trunc_mm, caster.reach_mm + 1.0)
    seen = np.unique(np.concatenate(seen)) if seen else np.zeros(0, np.int64)
    return {"vertices": v, "faces": f, "seen": seen, "kept": kept, "frames": int(kept.sum()), "poses": poses}


def video_partial(rng, scene, centerline, surface, config: VideoConfig, spread_mm: float, density: float,
                  margin_mm: float | None = None):
    """The ``video`` hole model for one segment: what it observed and the fused partial points.

    Parameters
    ----------
    rng : numpy.random.Generator
    scene : SurfaceScene
        The whole colon.
    centerline : Centerline
        The colon's centerline.
    surface : SegmentSurface
    config : VideoConfig
    spread_mm : float
        The withdrawal starts and ends this far beyond the segment (arc length, mm).
    density : float
        Points per mm^2 sampled on the fused surface.
    margin_mm : float, optional
        Fused faces nearest to the centerline farther than this outside the
        window are another stretch's (default: the segment cut's margin).

    Returns
    -------
    observed : (f,) bool
        Per face of ``surface.mesh``: its parent face was seen by a kept frame.
    partial : (n, 3) float, mm
    info : dict
        The degradation settings, frame counts and trajectory summary.
    """
    from colonbench.meshes import sample_surface
    from colonbench.datagen.segments import STRETCH_MARGIN_MM, clip_faces
    from colonbench.video.withdrawal import FrameCaster, Intrinsics, withdrawal

    margin_mm = STRETCH_MARGIN_MM if margin_mm is None else margin_mm
    s0, s1 = surface.window
    intr = Intrinsics.wide(config.image_px, fov_deg=config.fov_deg)
    traj = withdrawal(rng, scene, centerline, max(s0 - spread_mm, 0.0), min(s1 + spread_mm, centerline.length),
                      config)
    anchor = int(np.argmin(np.abs(traj.arclength - 0.5 * (s0 + s1))))
    settings = degradation(rng, config)
    caster = FrameCaster(scene, intr, config.near_mm, settings["reach_mm"], settings["max_incidence_deg"])
    parents = np.unique(surface.parent_face)
    fused = fused_video(rng, caster, traj, settings, config, anchor, candidates=parents)
    seen = np.zeros(len(scene.faces), bool)
    seen[fused["seen"]] = True
    observed = seen[surface.parent_face]

    # the fused surface between the segment's planes, on its own stretch of the colon
    v, f = fused["vertices"], fused["faces"]
    c0, c1 = centerline.point_at([s0, s1])
    t0, t1 = centerline.tangent_at([s0, s1])
    if len(f):
        cent = v[f].mean(axis=1)
        _, s_near = centerline.closest(cent)
        near = (s_near >= s0 - margin_mm) & (s_near <= s1 + margin_mm)
        v, f, _ = clip_faces(v, f[near], np.zeros(int(near.sum()), np.int64), c0, t0)
        v, f, _ = clip_faces(v, f, np.zeros(len(f), np.int64), c1, -t1)
    partial = sample_surface(rng, v, f, density=density) if len(f) else np.zeros((0, 3))
    info = {**settings, "frames": len(traj), "frames_fused": fused["frames"],
            "arclength_mm": [float(traj.arclength.min()), float(traj.arclength.max())],
            "seconds": float(traj.times[-1]) if len(traj) else 0.0}
    return observed, partial, info
