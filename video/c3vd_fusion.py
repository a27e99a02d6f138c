"""A reconstruction-like partial of a C3VD sequence: its depth frames and poses fused by TSDF, as the ``video``
hole model fuses rendered frames (:func:`colonbench.video.fusion.tsdf_fuse`).

open3d's TSDF integrates pinhole depth images, and C3VD's camera is a fisheye. Each fused frame is therefore
resampled into a virtual pinhole camera with the same pose: a pinhole pixel takes the z depth of the fisheye pixel
nearest to its ray (the two cameras share their axes, so z is the same quantity). The pinhole's field of view is
the fisheye's at the middles of the image's edges (C3VD's: about 64 degrees left and right of the axis, 46 up and
down), at most :data:`MAX_HALF_ANGLE_DEG`; what the fisheye sees beyond it (the corners) is not fused. Only every
``every``-th frame is fused, and at ``width_px`` pixels across: the surface is made at the TSDF's voxel (1 mm)
from frames a few millimetres of withdrawal apart, so a faster build loses only what a skipped frame alone
showed and detail finer than the voxel.
"""

from __future__ import annotations

import numpy as np

from colonbench.video.c3vd import DEPTH_RANGE_MM, read_depth
from colonbench.video.fisheye import Fisheye
from colonbench.video.fusion import tsdf_fuse
from colonbench.video.withdrawal import Intrinsics

#: The virtual pinhole's widest half field of view, degrees.
MAX_HALF_ANGLE_DEG = 70.0
#: Defaults: every 5th frame, 240 pixels across, the video hole model's TSDF (1 mm voxels, 4 mm truncation).
EVERY = 5
WIDTH_PX = 240
VOXEL_MM = 1.0
TRUNC_MM = 4.0
#: Depth below which nothing is fused, mm (the video hole model's near limit).
NEAR_MM = 2.0


def pinhole_for(fisheye: Fisheye, width_px: int = WIDTH_PX) -> tuple[Intrinsics, np.ndarray]:
    """The virtual pinhole of a fisheye camera and, per pinhole pixel, the fisheye pixel it reads.

    Returns
    -------
    intrinsics : Intrinsics
        Square pixels, ``width_px`` across, principal point at the centre.
    index : (height * width,) int
        Row-major index into the fisheye image of the pixel nearest to each pinhole pixel's ray; -1 where the
        fisheye has none.
    """
    cap = np.radians(MAX_HALF_ANGLE_DEG)
    hx, hy = (min(a, cap) for a in fisheye.half_angles())
    f = 0.5 * width_px / np.tan(hx)
    height = max(2, int(round(2 * f * np.tan(hy))))
    intr = Intrinsics(int(width_px), height, float(f), float(f), (width_px - 1) / 2.0, (height - 1) / 2.0)
    uv = np.rint(fisheye.project(intr.rays()))
    ok = np.isfinite(uv).all(axis=1)
    iu = np.where(ok, uv[:, 0], -1).astype(np.int64)
    iv = np.where(ok, uv[:, 1], -1).astype(np.int64)
    ok &= (iu >= 0) & (iu < fisheye.width) & (iv >= 0) & (iv < fisheye.height)
    return intr, np.where(ok, iv * fisheye.width + iu, -1)


def resample(depth: np.ndarray, intr: Intrinsics, index: np.ndarray, near_mm: float = NEAR_MM) -> np.ndarray:
    """A fisheye depth frame (z, mm) as the virtual pinhole sees it: (height, width) float32, 0 where invalid."""
    flat = np.asarray(depth, np.float32).ravel()
    out = np.where(index >= 0, flat[np.maximum(index, 0)], np.float32(0))
    out[out < near_mm] = 0
    return out.reshape(intr.height, intr.width)


def fuse_sequence(depth_files, poses, fisheye: Fisheye, every: int = EVERY, width_px: int = WIDTH_PX,
                  voxel_mm: float = VOXEL_MM, trunc_mm: float = TRUNC_MM, progress=None) -> dict:
    """Fuse every ``every``-th depth frame of a sequence.

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
    progress : callable, optional
        Called with 1 after each frame.

    Returns
    -------
    dict
        ``vertices`` (v, 3) mm, ``faces`` (f, 3), ``frames`` (the indices fused), ``pinhole`` (its intrinsics).
    """
    if every < 1:
        raise ValueError(f"every must be >= 1, got {every}")
    intr, index = pinhole_for(fisheye, width_px)
    frames = list(range(0, len(depth_files), every))

    def depths():
        for k in frames:
            yield resample(read_depth(depth_files[k], fisheye), intr, index)
            if progress is not None:
                progress(1)

    v, f = tsdf_fuse(depths(), np.asarray(poses, float)[frames], intr, voxel_mm, trunc_mm, DEPTH_RANGE_MM)
    return {"vertices": v, "faces": f, "frames": frames, "pinhole": intr.to_dict()}
