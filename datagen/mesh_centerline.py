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


def compute_centerline(mesh: trimesh.Trimesh, voxel_mm: float = 1.0, smooth_mm: float = 3.0,
                       require_closed: bool = True) -> Centerline:
    """Centerline of a closed tubular mesh by the minimal path between its geodesic extremities.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Closed (watertight) lumen surface, mm.
    voxel_mm : float
        Voxel size; must resolve the narrowest part of the lumen.
    smooth_mm : float
        Gaussian smoothing of the voxel path.
    require_closed : bool
        Refuse a mesh that is not watertight (:func:`open_tube_centerline` closes an open tube first and lets
        the small flaws of a real mesh through: the lumen is voxelized by ray parity).

    Returns
    -------
    Centerline
        Resampled at 0.5 mm. Its ends stop where the lumen narrows to half its
        median radius along the path (the poles of a closed colon).
    """
    import edt
    from colonbench import paths

    if require_closed and not mesh.is_watertight:
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


def boundary_loops(faces) -> list[np.ndarray]:
    """The closed loops of a triangle mesh's boundary edges (edges of one face), each (k,) int in the order its
    faces run along it.

    Raises
    ------
    InputError
        The boundary does not form simple loops (a vertex where two boundaries meet).
    """
    f = np.asarray(faces, np.int64)
    directed = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    key = np.sort(directed, axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    edges = directed[counts[inverse.ravel()] == 1]
    nxt = {}
    for a, b in edges:
        if a in nxt:
            raise InputError(f"the mesh's boundary meets itself at vertex {a}: its open ends cannot be closed")
        nxt[int(a)] = int(b)
    loops, left = [], set(nxt)
    while left:
        start = min(left)
        loop, v = [], start
        while True:
            loop.append(v)
            left.discard(v)
            v = nxt.get(v)
            if v is None:
                raise InputError("the mesh's boundary is not closed loops: its open ends cannot be closed")
            if v == start:
                break
        loops.append(np.array(loop, np.int64))
    return loops


def cap_open_ends(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """The mesh with every boundary loop closed by a fan from the loop's centroid (orientation kept)."""
    vertices, faces = np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64)
    new_v, new_f = [vertices], [faces]
    n = len(vertices)
    for loop in boundary_loops(faces):
        centre = n
        new_v.append(vertices[loop].mean(axis=0)[None])
        n += 1
        # a face runs along its boundary edge a -> b; the cap's triangle runs b -> a
        new_f.append(np.stack([np.roll(loop, -1), loop, np.full(len(loop), centre)], axis=1))
    return trimesh.Trimesh(np.concatenate(new_v), np.concatenate(new_f), process=False)


def open_tube_centerline(mesh: trimesh.Trimesh, voxel_mm: float = 1.0, smooth_mm: float = 3.0) -> Centerline:
    """The centerline of an open tube (a phantom's segment, open at its ends): its ends closed by flat caps
    (:func:`cap_open_ends`), then :func:`compute_centerline`; its ends stop about half a radius inside the
    caps."""
    return compute_centerline(cap_open_ends(mesh), voxel_mm, smooth_mm, require_closed=False)
