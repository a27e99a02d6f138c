"""A colonoscopy frame dataset on disk: RGB, depth, poses, intrinsics and per-frame visibility of a withdrawal.

Layout of a dataset folder (``colonbench video``)
-------------------------------------------------
``rgb/NNNNNN.png``
    8-bit RGB frames (:mod:`colonbench.video.mucosa`).
``depth/NNNNNN.png``
    16-bit grey PNG, depth in steps of :data:`DEPTH_UNIT_MM` (0.1 mm): value
    ``v`` is a z-depth of ``v / 10`` mm; 0 where no surface is seen. Depths
    beyond 6553.5 mm are written 0.
``faces/NNNNNN.npz`` (with ``--face-ids``)
    ``face``: (height, width) int32, the face of ``colon.ply`` under each
    pixel, -1 where none.
``poses.txt``
    TUM trajectory, one line per frame: ``timestamp tx ty tz qx qy qz qw``,
    seconds and mm, camera-to-world (``X_world = R X_cam + t``), camera axes as
    in OpenCV (x right, y down, z forward); scalar-last quaternion.
``intrinsics.json``
    ``width``, ``height``, ``fx``, ``fy``, ``cx``, ``cy`` (pixels, pixel centres at
    integer coordinates), ``K``, ``depth_unit_mm``, ``fov_diagonal_deg``.
``visibility.npz``
    ``offsets`` (frames + 1,) int64 and ``faces`` int32: the faces frame ``i``
    sees are ``faces[offsets[i]:offsets[i + 1]]``, indices into ``colon.ply``
    (the rule of :class:`colonbench.video.withdrawal.FrameCaster`).
``colon.ply``, ``centerline.npy``
    The colon surface and its centerline (arc length 0 at the caecum), mm, the
    world frame of the poses.
``video.json``
    What was made: the colon's source, the stretch, speeds, the trajectory's
    drawn values, the conventions, timing.
``preview.gif``
    The first seconds, RGB beside colour-mapped depth.

The world frame is the colon mesh's, right-handed, in mm; no axis is "up".
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from colonbench import seeding
from colonbench.datagen.config import VideoConfig
from colonbench.errors import InputError

#: Depth PNG step, mm.
DEPTH_UNIT_MM = 0.1
#: Depth shown darkest in the preview, mm.
PREVIEW_DEPTH_MM = 80.0
#: Frames rendered with one colour scene; each scene holds the faces within ``far_mm`` of its frames.
CHUNK_FRAMES = 120


def depth_to_png(depth) -> np.ndarray:
    """(h, w) uint16 of a depth image in mm: steps of :data:`DEPTH_UNIT_MM`, 0 where invalid or too far."""
    d = np.round(np.asarray(depth, float) / DEPTH_UNIT_MM)
    return np.where((d > 0) & (d <= 65535), d, 0).astype(np.uint16)


def png_to_depth(values) -> np.ndarray:
    """(h, w) float depth in mm of a depth PNG's values (0 stays 0: no surface)."""
    return np.asarray(values, float) * DEPTH_UNIT_MM


def _write_png(path, array) -> None:
    from PIL import Image

    array = np.asarray(array)
    Image.fromarray(array).save(path, optimize=False, compress_level=3)  # uint16 gives a 16-bit grey PNG


def preview_frame(rgb, depth, max_depth_mm: float) -> np.ndarray:
    """RGB beside the depth colour-mapped (near bright, far dark; black where none); (h, 2 w, 3) uint8."""
    from matplotlib import colormaps

    d = np.asarray(depth, float)
    t = np.clip(1.0 - d / max_depth_mm, 0.0, 1.0)
    col = (np.asarray(colormaps["magma"](t))[..., :3] * 255).astype(np.uint8)
    col[d <= 0] = 0
    return np.concatenate([np.asarray(rgb, np.uint8), col], axis=1)


def _thumbnail(frame, height: int) -> np.ndarray:
    """A frame scaled to ``height`` px high (Lanczos)."""
    from PIL import Image

    image = Image.fromarray(frame)
    width = int(round(image.width * height / image.height))
    return np.asarray(image.resize((width, height), Image.Resampling.LANCZOS))


def write_gif(path, frames, fps: float) -> Path:
    """An animated GIF of (h, w, 3) uint8 frames at ``fps``, looping."""
    from PIL import Image

    images = [Image.fromarray(f).convert("P", palette=Image.Palette.ADAPTIVE, colors=192) for f in frames]
    if not images:
        raise InputError("no frames to write into a GIF")
    images[0].save(path, save_all=True, append_images=images[1:], duration=int(round(1000 / fps)), loop=0,
                   optimize=True)
    return Path(path)


def write_video(colon, out, seed: int = 0, start_mm: float | None = None, end_mm: float | None = None,
                config: VideoConfig | None = None, size: int = 256, fps: float = 15.0,
                face_ids: bool = False, max_frames: int | None = None, gif_seconds: float = 10.0,
                gif_size: int = 160, far_mm: float = 120.0, source: dict | None = None,
                progress: bool = True) -> dict:
    """Render a withdrawal through a colon into a frame dataset (see the module's description).

    Parameters
    ----------
    colon : Colon
        Its centerline runs from the caecum (arc length 0).
    out : path
        Folder to write (created; files of a previous dataset there are replaced).
    seed : int
        Root of the trajectory's and the texture's draws
        (``seeding.rng(seed, "video", ...)``).
    start_mm, end_mm : float, optional
        The stretch withdrawn through, arc length (default: the whole colon).
    config : VideoConfig
        Speeds, looking around, field of view.
    size : int
        Frame side, px.
    fps : float
        Frames per second of the examination's time.
    face_ids : bool
        Also write the face under every pixel.
    max_frames : int, optional
        Stop after this many frames.
    gif_seconds, gif_size : float, int
        Length (s) and frame height (px) of ``preview.gif`` (0 s: none).
    far_mm : float
        Colour frames show the surface up to this far from the camera.
    source : dict, optional
        Where the colon came from, recorded in ``video.json``.

    Returns
    -------
    dict
        The content of ``video.json``.
    """
    from colonbench.datagen.camera import SurfaceScene
    from colonbench.progress import bar as progress_bar
    from colonbench.video.mucosa import ColourRenderer, mucosa_colours
    from colonbench.video.withdrawal import FrameCaster, Intrinsics, pose_to_tum, withdrawal

    config = config or VideoConfig()
    length = colon.centerline.length
    start = 0.0 if start_mm is None else float(start_mm)
    end = length if end_mm is None else float(end_mm)
    if not 0.0 <= start < end <= length + 1e-6:
        raise InputError(f"the stretch {start:g}-{end:g} mm is not inside the colon's centerline (0-{length:.0f} mm)")
    if size < 16:
        raise InputError(f"frames of {size} px are too small; use 16 px or more")
    t0 = time.perf_counter()
    out = Path(out)
    for sub in ("rgb", "depth", "faces"):
        (out / sub).mkdir(parents=True, exist_ok=True)
        for old in (out / sub).glob("*"):
            old.unlink()
    v, f = np.asarray(colon.mesh.vertices, float), np.asarray(colon.mesh.faces, np.int64)
    scene = SurfaceScene(v, f)
    intr = Intrinsics.wide(size, fov_deg=config.fov_deg)
    traj = withdrawal(seeding.rng(seed, "video", "trajectory"), scene, colon.centerline, start, end, config, fps)
    n = len(traj) if max_frames is None else min(len(traj), int(max_frames))
    caster = FrameCaster(scene, intr, config.near_mm, config.reach_mm[1])
    colours = mucosa_colours(v, seed)
    inward = -colon.mesh.vertex_normals
    gif_n = min(n, int(round(gif_seconds * fps)))
    offsets, seen_all, gif = [0], [], []
    timing = {"depth": 0.0, "visibility": 0.0, "rgb": 0.0, "write": 0.0}
    bar = progress_bar(total=n, unit="frame", desc="video", enabled=progress)
    renderer = ColourRenderer(intr, far_mm=far_mm)
    try:
        for c0 in range(0, n, CHUNK_FRAMES):
            c1 = min(c0 + CHUNK_FRAMES, n)
            # the faces near this chunk's cameras: a light scene for the rasteriser
            near, _ = cKDTree(traj.positions[c0:c1]).query(scene.centroids, distance_upper_bound=far_mm)
            used, local = np.unique(f[np.isfinite(near)], return_inverse=True)
            renderer.set_mesh(v[used], local.reshape(-1, 3), colours[used], inward=inward[used])
            for i in range(c0, c1):
                pose = traj.poses[i]
                t = time.perf_counter()
                depth, face = caster.depth(pose)
                t1 = time.perf_counter()
                seen = caster.seen(pose)
                t2 = time.perf_counter()
                rgb = renderer.render(pose, depth)
                t3 = time.perf_counter()
                _write_png(out / "rgb" / f"{i:06d}.png", rgb)
                _write_png(out / "depth" / f"{i:06d}.png", depth_to_png(depth))
                if face_ids:
                    np.savez_compressed(out / "faces" / f"{i:06d}.npz", face=face)
                seen_all.append(seen.astype(np.int32))
                offsets.append(offsets[-1] + len(seen))
                if i < gif_n:
                    gif.append(_thumbnail(preview_frame(rgb, depth, PREVIEW_DEPTH_MM), gif_size))
                timing["depth"] += t1 - t
                timing["visibility"] += t2 - t1
                timing["rgb"] += t3 - t2
                timing["write"] += time.perf_counter() - t3
                bar.update(1)
    finally:
        renderer.close()
    bar.close()
    if not face_ids:
        (out / "faces").rmdir()
    (out / "poses.txt").write_text(
        "# colonbench video: timestamp tx ty tz qx qy qz qw (s, mm; camera-to-world, OpenCV camera axes)\n"
        + "\n".join(pose_to_tum(traj.times[i], traj.poses[i]) for i in range(n)) + "\n")
    (out / "intrinsics.json").write_text(json.dumps(
        {**intr.to_dict(), "K": intr.matrix().tolist(), "depth_unit_mm": DEPTH_UNIT_MM,
         "fov_diagonal_deg": config.fov_deg,
         "convention": "OpenCV pinhole: u = fx x / z + cx (column), v = fy y / z + cy (row), pixel centres at "
                       "integer coordinates; depth is z in the camera frame"}, indent=1))
    np.savez_compressed(out / "visibility.npz", offsets=np.asarray(offsets, np.int64),
                        faces=np.concatenate(seen_all) if seen_all else np.zeros(0, np.int32))
    colon.mesh.export(out / "colon.ply")
    np.save(out / "centerline.npy", colon.centerline.points)
    if gif:
        write_gif(out / "preview.gif", gif, fps)
    seconds = time.perf_counter() - t0
    meta = {"source": source or {}, "seed": seed, "stretch_mm": [start, end], "frames": n, "fps": fps,
            "duration_s": float(traj.times[n - 1]) if n else 0.0, "size_px": size, "face_ids": face_ids,
            "config": {k: list(val) if isinstance(val, tuple) else val for k, val in vars(config).items()},
            "depth_unit_mm": DEPTH_UNIT_MM, "seconds": {"total": seconds, **timing},
            "frames_per_second": n / seconds if seconds > 0 else None,
            "conventions": "mm and s; poses camera-to-world with OpenCV camera axes (x right, y down, z forward); "
                           "depth PNG value / 10 = z in mm, 0 = none; TUM quaternions scalar-last"}
    (out / "video.json").write_text(json.dumps(meta, indent=1))
    return meta
