"""The centerline of a closed colon mesh, computed where none is given.

The classic recipe for tubular organs (the paper used "a classic skeleton extraction"): voxelize the lumen,
take its two geodesically farthest voxels as the ends (double sweep), and follow the minimal path between them
with the distance to the wall as speed (:mod:`colonbench.paths`), so the path keeps to the middle of the lumen."""

from __future__ import annotations

import numpy as np
import trimesh

from colonbench.datagen.camera import SurfaceScene
from colonbench.errors import InputError
from colonbench.polyline import Centerline


def voxelize_lumen(mesh: trimesh.Trimesh, voxel_mm: float = 1.0):
    """Occupancy of the lumen of a closed mesh on a regular grid.

    Returns
    -------
    inside : (X, Y, Z) bool
    origin : (3,) float
        Centre of voxel (0, 0, 0), mm.
    """
    from scipy.ndimage import binary_fill_holes

    lo = mesh.bounds[0] - 2 * voxel_mm
    shape = np.ceil((mesh.bounds[1] + 2 * voxel_mm - lo) / voxel_mm).astype(int) + 1
    surf = mesh.voxelized(voxel_mm)  # surface voxels
    idx = np.round((surf.points - lo) / voxel_mm).astype(int)
    grid = np.zeros(shape, dtype=bool)
    grid[tuple(np.clip(idx, 0, shape - 1).T)] = True
    # the filled surface voxels are a superset: keep the voxels whose centres
    # are inside, so that two loops touching within a voxel stay apart
    cand = np.argwhere(binary_fill_holes(grid))
    inside = SurfaceScene(mesh.vertices, mesh.faces).occupancy(lo + cand * voxel_mm, nsamples=3)
    out = np.zeros(shape, dtype=bool)
    out[tuple(cand[inside].T)] = True
    return out, lo


def compute_centerline(mesh: trimesh.Trimesh, voxel_mm: float = 1.0, smooth_mm: float = 3.0) -> Centerline:
    """Centerline of a closed tubular mesh by the minimal path between its geodesic extremities.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Closed (watertight) lumen surface, mm.
    voxel_mm : float
        Voxel size; must resolve the narrowest part of the lumen.
    smooth_mm : float
        Gaussian smoothing of the voxel path.

    Returns
    -------
    Centerline
        Resampled at 0.5 mm. Its ends stop where the lumen narrows to half its
        median radius along the path (the poles of a closed colon).
    """
    import edt
    from colonbench import paths

    if not mesh.is_watertight:
        raise InputError("computing a centerline needs a closed (watertight) mesh; give the centerline instead")
    inside, origin = voxelize_lumen(mesh, voxel_mm)
    if not inside.any():
        raise InputError("the mesh encloses no voxels at this resolution; try a smaller voxel size")
    inside = paths.largest_component(inside)
    dist = edt.edt(inside, anisotropy=(voxel_mm,) * 3)
    vox = paths.middle_path(inside, dist, *paths.extremities(inside, dist, voxel_mm), voxel_mm)
    # geodesic extremities lie on the wall (the rim of a pole): trim each end to
    # where the path is at least half its median distance away from the wall
    wall = dist[tuple(vox.T)]
    deep = np.flatnonzero(wall >= 0.5 * np.median(wall))
    vox = vox[deep[0]: deep[-1] + 1]
    pts = origin + paths.smooth_path(vox, smooth_mm / voxel_mm) * voxel_mm
    return Centerline.from_points(pts).resample(0.5)
