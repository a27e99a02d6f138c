"""Reading and writing point clouds and meshes a user hands us: PLY, OBJ, STL, OFF, NPY, XYZ, in mm."""

from __future__ import annotations

import itertools
import warnings
from pathlib import Path

import numpy as np

from colonbench.errors import InputError

#: File types ``read_surface`` understands: point clouds (``.npy``, text: ``.xyz``, ``.txt``, ``.csv``, a
#: ``.ply`` without faces) and meshes (``.ply`` or ``.obj`` with faces, ``.stl`` and ``.off``: what CT
#: segmentation tools such as 3D Slicer export).
SURFACE_SUFFIXES = (".ply", ".obj", ".stl", ".off", ".npy", ".xyz", ".txt", ".csv")
#: Text lines that start with these are comments (CloudCompare writes its header as ``//X Y Z``); ``//``
#: only before the first row of numbers.
TEXT_COMMENTS = ("#", "//")
#: A mesh is sampled at this density (points/mm^2), the paper's and the shipped model's.
MESH_DENSITY = 2.0


def read_surface(path, seed: int = 0) -> tuple[np.ndarray, int]:
    """The points of a user's surface file, mm: a point cloud, or a mesh sampled on its faces.

    A mesh is sampled uniformly on its faces at :data:`MESH_DENSITY` points/mm^2
    (seeded by ``seed``), so that the coarse faces of a fused surface reach a
    method as the clouds it was trained on, whatever the mesh's vertex
    spacing. Rows that are not finite (NaN or infinite: invalid depth in a
    reconstruction) are dropped and counted.

    Returns
    -------
    points : (n, 3) float64
    dropped : int
        Rows dropped for not being finite.

    Raises
    ------
    InputError
        For a missing file, an unknown type, or content that is not x, y, z.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if path.is_dir():
        raise InputError(f"{path}: a folder, not a file; give the point cloud or mesh file(s) in it")
    if suffix not in SURFACE_SUFFIXES:
        raise InputError(f"{path}: unknown file type {suffix!r}; use one of {', '.join(SURFACE_SUFFIXES)}")
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    if path.stat().st_size == 0:
        raise InputError(f"{path}: the file is empty (0 bytes): no points to read")
    try:
        if suffix == ".npy":
            pts = np.load(path, allow_pickle=False)
        elif suffix in (".xyz", ".txt", ".csv"):
            pts = read_text_table(path)
        else:
            pts = _mesh_or_cloud(path, suffix, seed)
    except InputError:
        raise
    except Exception as exc:  # noqa: BLE001 - numpy/trimesh raise many types for a bad file
        if suffix == ".ply" and isinstance(exc, KeyError):   # trimesh looks a PLY's vertex properties up by name
            raise InputError(f"{path}: could not read points: no vertex property {exc} (a PLY's vertices need "
                             "x, y and z)") from None
        raise InputError(f"{path}: could not read points ({type(exc).__name__}: {exc})") from None
    pts = np.asarray(pts)
    if pts.ndim != 2 or pts.shape[1] != 3 or not np.issubdtype(pts.dtype, np.number):
        raise InputError(f"{path}: expected (n, 3) x, y, z values, got an array of shape {pts.shape}")
    pts = pts.astype(np.float64)
    finite = np.isfinite(pts).all(axis=1)
    return pts[finite], int(np.count_nonzero(~finite))


def read_text_table(path, columns: int | None = 3, what: str = "x, y, z numbers") -> np.ndarray:
    """A table of numbers from a text file; (n, columns) float, or every column when ``columns`` is None.

    Columns are separated by spaces, tabs, commas or semicolons; one header line of names (``x,y,z``,
    CloudCompare's ``//X Y Z``) may come first, and lines starting with ``#`` are comments (``//`` too before
    the first row of numbers). With ``columns``, further columns (colours, normals) are ignored.

    Raises
    ------
    InputError
        Naming the first line (numbered as in the file) that is not ``what``.
    """
    path = Path(path)

    with open(path, encoding="utf-8", errors="replace") as fh:   # the first two lines that are not comments
        head = list(itertools.islice(((n, line) for n, raw in enumerate(fh, start=1)
                                      if (line := raw.strip()) and not line.startswith(TEXT_COMMENTS)), 2))
    empty = np.zeros((0, columns or 0))
    if not head:
        return empty
    # semicolons first: a table written with decimal commas separates its columns with them
    delimiter = next((d for d in (";", ",") if any(d in line for _, line in head)), None)

    def numbers(fields):
        try:
            [float(x) for x in fields]   # "nan" and "inf" parse: the caller decides what to do with them
            return True
        except ValueError:
            return False

    header = not numbers(head[0][1].split(delimiter))   # a first line of column names
    if header and len(head) < 2:
        return empty   # only a header
    first, row = head[1] if header else head[0]   # the first row of numbers: its line number, and its width
    width = len(row.split(delimiter))
    usecols = tuple(range(columns)) if columns else None

    def good(line):
        fields = line.split(delimiter)
        return (len(fields) >= columns if columns else len(fields) == width) and numbers(fields[:columns])

    # everything before the first row of numbers is skipped (comments, a header); after it only "#" comments
    # (numpy's parser slows down threefold with two comment markers)
    try:
        with warnings.catch_warnings():  # nothing but "#" comments after the first row: 0 rows
            warnings.simplefilter("ignore", UserWarning)
            return np.loadtxt(path, delimiter=delimiter, comments="#", skiprows=first - 1, ndmin=2, usecols=usecols,
                              encoding="utf-8")
    except ValueError:
        with open(path, encoding="utf-8", errors="replace") as fh:
            lines = ((n, raw.strip()) for n, raw in enumerate(fh, start=1) if n >= first)
            n, line = next(((n, line) for n, line in lines if line and not line.startswith("#") and not good(line)),
                           (first, "?"))
        raise InputError(f"{path}: line {n} is not {what}: {line[:80]!r}") from None


def _mesh_or_cloud(path: Path, suffix: str, seed: int) -> np.ndarray:
    """A ``.ply``, ``.obj``, ``.stl`` or ``.off``: its faces sampled at :data:`MESH_DENSITY`, or its vertices
    if it has no faces (or too little area to sample)."""
    import trimesh

    geom = trimesh.load(path, process=False, force="mesh") if suffix == ".obj" else trimesh.load(path, process=False)
    faces = getattr(geom, "faces", None)
    vertices = getattr(geom, "vertices", None)
    if vertices is None or len(vertices) == 0:
        raise InputError(f"{path}: neither a point cloud nor a mesh (no vertices)")
    vertices = np.asarray(vertices, float)
    if faces is None or len(faces) == 0:
        return vertices
    from colonbench.meshes import sample_surface

    faces = np.asarray(faces)
    usable = np.isfinite(vertices[faces]).all(axis=(1, 2))   # a face on a NaN vertex has no area to sample
    points = sample_surface(np.random.default_rng(seed), vertices, faces[usable], density=MESH_DENSITY)
    # too little area for one sample (a mesh in metres has a millionth of its area in mm^2): its vertices,
    # so that the caller's unit check says what is wrong
    return points if len(points) else vertices


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
