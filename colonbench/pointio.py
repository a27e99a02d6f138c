"""Reading and writing point clouds and meshes a user hands us: PLY, NPY, XYZ, in mm."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from colonbench.errors import InputError

#: File types ``read_points`` understands.
POINT_SUFFIXES = (".ply", ".npy", ".xyz", ".txt")


def read_points(path) -> np.ndarray:
    """(n, 3) float64 points from a ``.ply`` (vertices of a point cloud or mesh), ``.npy`` or ``.xyz``/``.txt``.

    Raises
    ------
    InputError
        For a missing file, an unknown type, or content that is not x, y, z.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    suffix = path.suffix.lower()
    try:
        if suffix == ".npy":
            pts = np.load(path, allow_pickle=False)
        elif suffix in (".xyz", ".txt"):
            pts = np.loadtxt(path, ndmin=2, usecols=(0, 1, 2))
        elif suffix == ".ply":
            import trimesh

            geom = trimesh.load(path, process=False)
            if not hasattr(geom, "vertices"):
                raise InputError(f"{path}: a PLY file without vertices")
            pts = np.asarray(geom.vertices)
        else:
            raise InputError(f"{path}: unknown point file type {suffix!r}; use one of {', '.join(POINT_SUFFIXES)}")
    except InputError:
        raise
    except Exception as exc:  # noqa: BLE001 - numpy/trimesh raise many types for a bad file
        raise InputError(f"{path}: could not read points ({type(exc).__name__}: {exc})") from None
    pts = np.asarray(pts)
    if pts.ndim != 2 or pts.shape[1] != 3 or not np.issubdtype(pts.dtype, np.number):
        raise InputError(f"{path}: expected (n, 3) x, y, z values, got an array of shape {pts.shape}")
    return pts.astype(np.float64)


def write_mesh_ply(path, vertices, faces, colors=None) -> Path:
    """Write a triangle mesh (mm) as binary PLY, with optional (v, 3) uint8 vertex colours."""
    import trimesh

    mesh = trimesh.Trimesh(np.asarray(vertices, float), np.asarray(faces, np.int64), process=False)
    if colors is not None:
        mesh.visual.vertex_colors = np.concatenate([np.asarray(colors, np.uint8),
                                                    np.full((len(vertices), 1), 255, np.uint8)], axis=1)
    path = Path(path)
    mesh.export(path)
    return path
