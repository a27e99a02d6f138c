"""Import a real colon surface (PLY, STL, OBJ, OFF in mm) with or without a centerline.

Where no centerline is given, one is computed from the closed mesh
(:func:`colonbench.datagen.mesh_centerline.compute_centerline`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh

from colonbench.datagen.camera import SurfaceScene
from colonbench.datagen.colon import Colon
from colonbench.datagen.mesh_centerline import compute_centerline
from colonbench.errors import InputError
from colonbench.polyline import Centerline

MESH_SUFFIXES = (".ply", ".stl", ".obj", ".off")
CENTERLINE_SUFFIXES = (".npy", ".txt", ".csv", ".xyz")


def load_mesh(path) -> trimesh.Trimesh:
    """Read a triangle mesh in mm, checking that it is one.

    Raises
    ------
    InputError
        Missing or empty file, unknown format, no triangles (e.g. a point
        cloud), NaN or infinite coordinates, or a size that looks like metres.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise InputError(f"{path}: unsupported mesh format {path.suffix!r}; use one of {list(MESH_SUFFIXES)}")
    if path.stat().st_size == 0:
        raise InputError(f"{path}: the file is empty")
    try:
        loaded = trimesh.load(str(path), process=False)
    except Exception as exc:  # trimesh raises many kinds of errors on bad files
        raise InputError(f"{path}: could not be read as a mesh ({type(exc).__name__}: {exc})") from None
    if isinstance(loaded, trimesh.Scene):
        geoms = [g for g in loaded.geometry.values() if isinstance(g, trimesh.Trimesh)]
        loaded = trimesh.util.concatenate(geoms) if geoms else None
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise InputError(f"{path}: holds no triangles (a point cloud or an empty mesh?); a surface mesh is needed")
    mesh = loaded
    if path.suffix.lower() == ".stl":
        # STL stores every triangle with its own corners: weld them, or the
        # surface has no connectivity (we merge nothing else behind your back)
        mesh.merge_vertices()
    bad = ~np.isfinite(mesh.vertices).all(axis=1)
    if bad.any():
        raise InputError(f"{path}: {int(bad.sum())} vertices have NaN or infinite coordinates")
    extent = float(np.ptp(mesh.vertices, axis=0).max())
    if extent < 5.0:
        raise InputError(f"{path}: the mesh is only {extent:.3g} units across; colonbench expects millimetres "
                         "(is it in metres? multiply by 1000)")
    return mesh


def load_centerline(path) -> Centerline:
    """Read a centerline, an (n, 3) array in mm (``.npy``, or text with three columns as
    :func:`colonbench.pointio.read_text_table` reads them: a header line, any of its delimiters)."""
    from colonbench.pointio import read_text_table

    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    suffix = path.suffix.lower()
    if suffix not in CENTERLINE_SUFFIXES:
        raise InputError(f"{path}: unsupported centerline format {suffix!r}; use one of {list(CENTERLINE_SUFFIXES)}")
    try:
        if suffix == ".npy":
            pts = np.load(path, allow_pickle=False)
        else:
            pts = read_text_table(path, columns=None, what="x, y, z numbers of a centerline point")
    except InputError:
        raise
    except Exception as exc:
        raise InputError(f"{path}: could not be read as an (n, 3) array ({type(exc).__name__}: {exc})") from None
    pts = np.asarray(pts, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise InputError(f"{path}: a centerline must be an (n, 3) array of points, got shape {pts.shape}")
    try:
        return Centerline.from_points(pts)
    except InputError as exc:
        raise InputError(f"{path}: {exc}") from None


def check_centerline_inside(scene: SurfaceScene, centerline: Centerline, tolerance: float = 0.01) -> None:
    """Raise unless the centerline stays inside the lumen of a closed mesh.

    Parameters
    ----------
    tolerance : float
        Share of centerline samples allowed outside (CT midlines may graze the wall).

    Raises
    ------
    InputError
        Naming where (arc length, mm) the centerline leaves the mesh.
    """
    inside = scene.occupancy(centerline.points)
    outside = ~inside
    if outside.mean() > tolerance:
        s = centerline.arclength[outside]
        raise InputError(
            f"the centerline leaves the mesh: {outside.mean():.0%} of its points are outside the lumen "
            f"(first at arc length {s.min():.0f} mm, last at {s.max():.0f} mm of {centerline.length:.0f} mm)")


def import_colon(mesh_path, centerline_path=None, voxel_mm: float = 1.0, check: bool = True,
                 lumen: bool = False) -> Colon:
    """A :class:`Colon` from a user's surface mesh (mm) and, optionally, its centerline.

    Parameters
    ----------
    mesh_path : path
        PLY, STL, OBJ or OFF surface of the lumen, mm.
    centerline_path : path, optional
        ``.npy`` or text (n, 3) centerline, mm; computed when omitted.
    check : bool
        Verify that the centerline lies inside the lumen (by ray parity; for
        an open mesh up to a quarter of the points may read as outside).
    lumen : bool
        Keep only what colonoscopy sees (:func:`colonbench.datagen.lumen.import_lumen`):
        the lumen surface, remeshed at about ``voxel_mm``, with shells,
        duplicates and small gaps resolved, and the centerline (which must be
        given, as a rough midline) re-centred in the lumen. Collapsed
        stretches are listed in ``info["collapsed_mm"]``.
    """
    mesh = load_mesh(mesh_path)
    if lumen:
        from colonbench.datagen.lumen import import_lumen

        if centerline_path is None:
            raise InputError("importing the lumen needs a midline (centerline_path): it tells the lumen from the "
                             "space outside the colon")
        imported = import_lumen(mesh, load_centerline(centerline_path).points, voxel_mm=voxel_mm)
        return Colon(mesh=imported.mesh, centerline=imported.centerline, radius=imported.radius,
                     info={"source": Path(mesh_path).name, "centerline": "re-centred", **imported.info})
    scene = SurfaceScene(mesh.vertices, mesh.faces)
    if centerline_path is not None:
        centerline = load_centerline(centerline_path).resample(0.5)
        if check:
            # rays may leave an open mesh through its ends: a looser tolerance there
            check_centerline_inside(scene, centerline, tolerance=0.01 if mesh.is_watertight else 0.25)
        source = "given"
    else:
        centerline = compute_centerline(mesh, voxel_mm)
        source = "computed"
    d = scene.distance(centerline.points)
    return Colon(mesh=mesh, centerline=centerline, radius=np.full(len(centerline.points), np.nan),
                 info={"source": str(mesh_path), "centerline": source,
                       "median_wall_distance_mm": float(np.median(d))})
