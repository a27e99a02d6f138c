"""A synthetic sequence in C3VD's layout, with its exact truth: what the importer's tests and speed measurement read.

The depth frames are made by casting each pixel's fisheye ray (:class:`colonbench.video.fisheye.Fisheye`, exact
for the model) against the mesh in Embree (:class:`colonbench.datagen.camera.SurfaceScene`), not by the pinhole
renderer of :mod:`colonbench.video.withdrawal`: a pinhole image resampled into a fisheye would not be exact. The
files are written as C3VD's renderer writes them: ``coverage_mesh.obj`` with ``vt 0 0`` (index 1) on every face
the first hit of some pixel of some frame (no distance or angle limit) and ``vt 1 1`` (index 2) elsewhere;
``pose.txt`` with each camera-to-world matrix written column by column; 16-bit TIFF depth, ``floor(65535 *
clamp(z / 100 mm, 0, 1))``, 0 where a pixel meets nothing; ``camera_intrinsics.txt`` as lines ``name value``.
Arguments write it wrong on purpose (a pose file as written row by row, in metres; depth on another scale), as the
tests of the importer's checks need. :func:`write_screening` writes a C3VDv2 screening withdrawal as
:mod:`colonbench.video.c3vd_screening` reads one: ``pose.txt`` alone in its folder, the whole-colon mesh a plain
OBJ beside it (``cN_full_model/cN_full.obj``) or in it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh

from colonbench.polyline import Centerline
from colonbench.video.fisheye import Fisheye

#: C3VD's camera as its example loader gives it (sequence ``cecum_t4_b``; 1350 x 1080 pixels).
C3VD_CAMERA = Fisheye(1350, 1080, 678.544839263292, 542.975887548343, 769.243600037458, 0.0, -0.000812770624150226,
                      6.25674244578925e-07, -1.19662182144280e-09, 0.999986882249990, 0.00288273829525059,
                      -0.00296316513429569)


def phantom_tube(length_mm: float = 130.0, radius_mm: float = 12.0, bend_mm: float = 12.0, fold_every_mm: float = 16.0,
                 fold_depth: float = 0.3, ring_mm: float = 1.0, around: int = 48) -> tuple[trimesh.Trimesh, Centerline]:
    """An open tube like a phantom's segment: a gently bent centerline, ring folds that hide what lies behind them.

    Returns
    -------
    mesh : trimesh.Trimesh
        Open at both ends, normals out of the lumen, mm.
    centerline : Centerline
        The tube's own axis, mm.
    """
    from colonbench.datagen.tube import sweep

    def curve(t):
        t = np.asarray(t, float)
        return np.stack([t, bend_mm * np.sin(np.pi * t / length_mm), 0.2 * bend_mm * np.sin(2 * np.pi * t / length_mm)],
                        axis=1)

    line = Centerline.from_function(curve, 0.0, length_mm, ring_mm)
    s = line.arclength
    phase = (s / fold_every_mm) % 1.0
    fold = np.exp(-0.5 * ((phase - 0.5) * fold_every_mm / 1.5) ** 2)
    theta = 2 * np.pi * np.arange(around) / around
    radius = radius_mm * (1.0 - fold_depth * fold[:, None] * (0.75 + 0.25 * np.cos(3 * theta)[None, :]))
    return sweep(line, radius), line


def withdrawal_poses(centerline: Centerline, frames: int, start_mm: float | None = None, end_mm: float | None = None,
                     offset: float = 0.3, radius_mm: float = 12.0, tilt_deg: float = 25.0) -> np.ndarray:
    """Camera-to-world poses (frames, 4, 4) of a withdrawal from ``start_mm`` to ``end_mm`` of arc length, looking
    back up the tube (towards larger arc length), wandering off the axis and looking around (OpenCV axes, mm)."""
    start = centerline.length - 15.0 if start_mm is None else start_mm
    end = 15.0 if end_mm is None else end_mm
    s = np.linspace(start, end, frames)
    t = centerline.tangent_at(s)
    _, n, b = centerline.frames()
    n = np.stack([np.interp(s, centerline.arclength, n[:, k]) for k in range(3)], axis=1)
    b = np.cross(t, n)
    n = np.cross(b, t)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    k = np.arange(frames)
    phi = 2 * np.pi * k / max(frames / 2.0, 1.0)
    pos = centerline.point_at(s) + offset * radius_mm * (np.cos(phi)[:, None] * n + np.sin(phi)[:, None] * b)
    tilt = np.radians(tilt_deg) * np.sin(2 * np.pi * k / max(frames / 3.0, 1.0))
    psi = phi + np.pi
    z = np.cos(tilt)[:, None] * t + np.sin(tilt)[:, None] * (np.cos(psi)[:, None] * n + np.sin(psi)[:, None] * b)
    z /= np.linalg.norm(z, axis=1, keepdims=True)
    x = np.cross(b, z)
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    y = np.cross(z, x)
    poses = np.tile(np.eye(4), (frames, 1, 1))
    poses[:, :3, 0], poses[:, :3, 1], poses[:, :3, 2], poses[:, :3, 3] = x, y, z, pos
    return poses


def pixel_rays(fisheye: Fisheye) -> tuple[np.ndarray, np.ndarray]:
    """Unit camera-frame rays of every pixel with one, float32 (k, 3), and their row-major pixel indices (k,)."""
    u, v = fisheye.pixel_grid()
    rays = fisheye.rays(u.ravel(), v.ravel())
    ok = np.flatnonzero(np.isfinite(rays[:, 0]))
    return (rays[ok] / np.linalg.norm(rays[ok], axis=1, keepdims=True)).astype(np.float32), ok


def render(scene, fisheye: Fisheye, pose, depth_range_mm: float = 100.0, rays=None) -> tuple[np.ndarray, np.ndarray]:
    """One frame as C3VD stores it, by casting every pixel's ray.

    Parameters
    ----------
    rays : tuple, optional
        :func:`pixel_rays` of ``fisheye``, made once for many frames.

    Returns
    -------
    depth : (height, width) uint16
        ``floor(65535 * clamp(z / depth_range_mm, 0, 1))``; 0 where the ray meets nothing.
    faces : (k,) int
        The faces some pixel's ray meets first (at any distance).
    """
    unit, where = pixel_rays(fisheye) if rays is None else rays
    pose = np.asarray(pose, float)
    t, face = scene.cast(np.broadcast_to(pose[:3, 3], unit.shape), unit @ pose[:3, :3].T.astype(np.float32))
    hit = face >= 0
    z = np.where(hit, t * unit[:, 2], 0.0)
    value = np.where(hit, np.floor(65535.0 * np.clip(z / depth_range_mm, 0.0, 1.0)), 0)
    depth = np.zeros(fisheye.width * fisheye.height, np.uint16)
    depth[where] = value.astype(np.uint16)
    return depth.reshape(fisheye.height, fisheye.width), np.unique(face[hit])


def write_obj(path, vertices, faces, observed) -> Path:
    """A coverage mesh as C3VD writes it: ``vt 0 0`` (index 1) observed, ``vt 1 1`` (index 2) unobserved."""
    path = Path(path)
    tex = np.where(np.asarray(observed, bool), 1, 2)
    f = np.asarray(faces, np.int64) + 1
    with open(path, "w") as fh:
        fh.write("".join(f"v {x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in np.asarray(vertices, float)))
        fh.write("vt 0.0 0.0\nvt 1.0 1.0\n")
        fh.write("".join(f"f {a}/{t} {b}/{t} {c}/{t}\n" for (a, b, c), t in zip(f, tex)))
    return path


def pose_lines(poses, as_written: bool = False, scale: float = 1.0) -> str:
    """``pose.txt``'s text: each camera-to-world matrix column by column as C3VD's renderer writes it (row by row
    where ``as_written``), its translation multiplied by ``scale`` (0.001: metres)."""
    out = []
    for m in np.asarray(poses, float):
        m = m.copy()
        m[:3, 3] *= scale
        out.append(",".join(f"{x:.9g}" for x in (m.ravel() if as_written else m.T.ravel())))
    return "\n".join(out) + "\n"


def write_sequence(folder, mesh: trimesh.Trimesh, poses, fisheye: Fisheye, layout: str = "v2",
                   as_written: bool = False, pose_scale: float = 1.0, depth_range_mm: float = 100.0,
                   intrinsics_dir=None, progress=None) -> np.ndarray:
    """Render and write one registered sequence in C3VD's layout; the exact per-face coverage.

    Parameters
    ----------
    folder : path
        The sequence's folder (created; its name is the sequence's).
    mesh : trimesh.Trimesh
        The phantom, mm (written with its vertices rounded to 1e-6 mm, and rendered so).
    poses : (n, 4, 4) float
        Camera-to-world, OpenCV axes, mm.
    fisheye : Fisheye
    layout : str
        ``v2`` (``depth/NNNN_depth.tiff``) or ``v1`` (``NNNN_depth.tiff`` beside ``pose.txt``).
    as_written, pose_scale
        Write the poses row by row, and their translation times ``pose_scale`` (wrong on purpose).
    depth_range_mm : float
        What 65535 stands for (C3VD: 100 mm; another value is a wrongly scaled depth).
    intrinsics_dir : path, optional
        Where ``camera_intrinsics.txt`` goes (default: the folder's parent, as in C3VDv2).
    progress : callable, optional
        Called with 1 after each frame.

    Returns
    -------
    (f,) bool
        Per face: the first hit of some pixel of some frame (what C3VD's coverage map records).
    """
    import tifffile

    from colonbench.datagen.camera import SurfaceScene

    folder = Path(folder)
    depth_dir = folder / "depth" if layout == "v2" else folder
    depth_dir.mkdir(parents=True, exist_ok=True)
    vertices = np.round(np.asarray(mesh.vertices, float), 6)
    scene = SurfaceScene(vertices, mesh.faces)
    seen = np.zeros(len(mesh.faces), bool)
    rays = pixel_rays(fisheye)
    for k, pose in enumerate(np.asarray(poses, float)):
        depth, faces = render(scene, fisheye, pose, depth_range_mm, rays)
        seen[faces] = True
        tifffile.imwrite(depth_dir / f"{k:04d}_depth.tiff", depth)
        if progress is not None:
            progress(1)
    write_obj(folder / "coverage_mesh.obj", vertices, mesh.faces, seen)
    (folder / "pose.txt").write_text(pose_lines(poses, as_written, pose_scale))
    where = Path(intrinsics_dir) if intrinsics_dir is not None else folder.parent
    (where / "camera_intrinsics.txt").write_text(fisheye.text())
    return seen


def write_mesh_obj(path, vertices, faces) -> Path:
    """A plain OBJ mesh (``v`` and ``f`` lines, no texture): a phantom's model as its download gives it."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    f = np.asarray(faces, np.int64) + 1
    with open(path, "w") as fh:
        fh.write("".join(f"v {x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in np.asarray(vertices, float)))
        fh.write("".join(f"f {a} {b} {c}\n" for a, b, c in f))
    return path


def write_screening(root, name: str, mesh: trimesh.Trimesh, poses, mesh_path=None, as_written: bool = False,
                    pose_scale: float = 1.0) -> tuple[Path, Path]:
    """Write one C3VDv2 screening withdrawal as its download is assumed to hold it
    (:mod:`colonbench.video.c3vd_screening`): ``root/<name>/pose.txt`` (no depth, no coverage mesh) and the
    whole-colon mesh as a plain OBJ, by default ``root/<colon>_full_model/<colon>_full.obj`` (its colon from
    the name's ``cN_full`` prefix).

    Parameters
    ----------
    mesh_path : path, optional
        Where the mesh goes instead (relative to ``root``), e.g. ``<name>/model.obj``; None with a mesh already
        written for another sequence of the colon writes it again, unchanged.
    as_written, pose_scale
        As :func:`write_sequence`: the poses row by row, their translation times ``pose_scale`` (wrong on purpose).

    Returns
    -------
    (folder, mesh file)
    """
    root = Path(root)
    folder = root / name
    folder.mkdir(parents=True, exist_ok=True)
    colon = name.split("_")[0]
    where = root / (mesh_path if mesh_path is not None else f"{colon}_full_model/{colon}_full.obj")
    write_mesh_obj(where, np.round(np.asarray(mesh.vertices, float), 6), mesh.faces)
    (folder / "pose.txt").write_text(pose_lines(poses, as_written, pose_scale))
    return folder, where
