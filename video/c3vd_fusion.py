"""A reconstruction-like partial of a C3VD sequence: its depth frames and poses fused by TSDF, as the ``video``
hole model fuses rendered frames (:func:`colonbench.video.fusion.tsdf_fuse`).

open3d's TSDF integrates pinhole depth images, and C3VD's camera is a fisheye whose image reaches 90 degrees from
its axis and beyond in the corners. Each fused frame is therefore resampled into five virtual pinholes sharing the
camera's centre, the faces of a cube around it (:func:`views_for`): one looking along the camera's axis and four
turned 90 degrees from it, right, left, down and up, each 90 degrees across. Together they hold every direction
of the fisheye's image that has a forward depth (C3VD's depth is z, so a ray at 90 degrees or more from the axis
has none). A view's pixel takes the depth of the fisheye pixel nearest its ray, converted from the camera's z to
the view's own (the point lies on the view's ray; :func:`resample`). The turned views are other poses of the same
frame (the pose times the view's rotation), so the TSDF integrates them as frames.

Every ``every``-th frame is fused, at ``width_px`` pixels across each view: the surface is made at the TSDF's
voxel (1 mm). A frame left out loses what it alone showed; the build measures what the fused surface reaches of
C3VD's coverage map and refuses a sequence's ``video`` samples where it falls short
(:mod:`colonbench.shards.c3vd_shards`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from colonbench.video.c3vd import DEPTH_RANGE_MM, read_depth
from colonbench.video.fisheye import Fisheye
from colonbench.video.fusion import tsdf_fuse
from colonbench.video.withdrawal import Intrinsics

#: Defaults: every 2nd frame, 128 pixels across each 90-degree view (about 1.1 pixel per degree at its centre,
#: as the one 240-pixel pinhole of importer version 1), the video hole model's TSDF (1 mm voxels, 4 mm truncation).
EVERY = 2
WIDTH_PX = 128
VOXEL_MM = 1.0
TRUNC_MM = 4.0
#: Depth below which nothing is fused, mm (the video hole model's near limit).
NEAR_MM = 2.0

#: The cube's faces: each view's rotation, its axes (x right, y down, z forward) in the camera's frame, columns.
_FRONT = np.eye(3)
_QUARTER = {"front": _FRONT,
            "right": np.array([[0.0, 0, 1], [0, 1, 0], [-1, 0, 0]]),
            "left": np.array([[0.0, 0, -1], [0, 1, 0], [1, 0, 0]]),
            "down": np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]]),
            "up": np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])}


@dataclass(frozen=True)
class View:
    """One virtual pinhole of a fused frame.

    Attributes
    ----------
    name : str
        ``front``, ``right``, ``left``, ``down`` or ``up``.
    rotation : (3, 3) float
        The view's axes in the camera's frame (columns): its pose is the frame's times this rotation.
    index : (height * width,) int
        Row-major index into the fisheye image of the pixel nearest to each view pixel's ray; -1 where none.
    factor : (height * width,) float32
        The view's z over the camera's z along each view pixel's ray (0 where ``index`` is -1).
    """

    name: str
    rotation: np.ndarray
    index: np.ndarray
    factor: np.ndarray


def views_for(fisheye: Fisheye, width_px: int = WIDTH_PX) -> tuple[Intrinsics, list[View]]:
    """The virtual pinholes of a fisheye camera: their shared intrinsics and the views that see some of its image.

    Returns
    -------
    intrinsics : Intrinsics
        Square, ``width_px`` across, 90 degrees across (focal length ``width_px / 2``), principal point at the
        centre.
    views : list of View
        The front view first; a turned view none of whose pixels the fisheye shows is left out.
    """
    w = int(width_px)
    f = 0.5 * w
    intr = Intrinsics(w, w, f, f, (w - 1) / 2.0, (w - 1) / 2.0)
    views = []
    for name, rot in _QUARTER.items():
        rays = intr.rays() @ rot.T                                   # in the camera's frame; view z = 1
        uv = np.rint(fisheye.project(rays))
        ok = np.isfinite(uv).all(axis=1) & (rays[:, 2] > 0)
        iu = np.where(ok, uv[:, 0], -1).astype(np.int64)
        iv = np.where(ok, uv[:, 1], -1).astype(np.int64)
        ok &= (iu >= 0) & (iu < fisheye.width) & (iv >= 0) & (iv < fisheye.height)
        if not ok.any():
            continue
        with np.errstate(divide="ignore"):
            factor = np.where(ok, 1.0 / rays[:, 2], 0.0).astype(np.float32)
        views.append(View(name, rot, np.where(ok, iv * fisheye.width + iu, -1), factor))
    return intr, views


def resample(depth: np.ndarray, intr: Intrinsics, view: View, near_mm: float = NEAR_MM) -> np.ndarray:
    """A fisheye depth frame (the camera's z, mm) as one virtual view sees it: (height, width) float32, the view's
    z, 0 where invalid (no fisheye pixel, no depth, or nearer than ``near_mm`` to the camera's plane)."""
    flat = np.asarray(depth, np.float32).ravel()
    z = np.where(view.index >= 0, flat[np.maximum(view.index, 0)], np.float32(0))
    z[z < near_mm] = 0
    return (z * view.factor).reshape(intr.height, intr.width)


def fuse_sequence(depth_files, poses, fisheye: Fisheye, every: int = EVERY, width_px: int = WIDTH_PX,
                  voxel_mm: float = VOXEL_MM, trunc_mm: float = TRUNC_MM, frames=None, progress=None) -> dict:
    """Fuse every ``every``-th depth frame of a sequence, each as its virtual views (:func:`views_for`).

    Parameters
    ----------
    depth_files : list of Path
        Frame ``k``'s C3VD depth file at ``[k]``.
    poses : (n, 4, 4) float
        Camera-to-world, column vectors, mm (the convention :func:`colonbench.video.c3vd.check_conventions`
        found applied).
    fisheye : Fisheye
    every, width_px : int
    voxel_mm, trunc_mm : float
        The TSDF's voxel and truncation, mm.
    frames : list of int, optional
        The frames to fuse, in place of every ``every``-th.
    progress : callable, optional
        Called with 1 after each frame.

    Returns
    -------
    dict
        ``vertices`` (v, 3) mm, ``faces`` (f, 3), ``frames`` (the indices fused), ``pinhole`` (the views'
        intrinsics), ``views`` (their names).
    """
    if every < 1:
        raise ValueError(f"every must be >= 1, got {every}")
    intr, views = views_for(fisheye, width_px)
    frames = list(range(0, len(depth_files), every)) if frames is None else [int(k) for k in frames]
    poses = np.asarray(poses, float)
    # the camera's depth range as a view's z (z times the view's factor): nothing the camera recorded is cut
    reach = DEPTH_RANGE_MM * max(float(view.factor.max()) for view in views)
    turned = np.tile(np.eye(4), (len(views), 1, 1))
    turned[:, :3, :3] = [v.rotation for v in views]

    def images():
        for k in frames:
            depth = read_depth(depth_files[k], fisheye)
            for view in views:
                yield resample(depth, intr, view)
            if progress is not None:
                progress(1)

    view_poses = (poses[frames][:, None] @ turned[None]).reshape(-1, 4, 4)
    v, f = tsdf_fuse(images(), view_poses, intr, voxel_mm, trunc_mm, reach)
    return {"vertices": v, "faces": f, "frames": frames, "pinhole": intr.to_dict(),
            "views": [view.name for view in views]}
