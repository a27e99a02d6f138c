"""A whole reconstruction and its camera trajectory, read and checked (units, frame) for ``colonbench map``."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from colonbench.errors import InputError
from colonbench.pointio import read_text_table

#: Points within this bounding-box diagonal (in the file's unit) are taken for metres.
METRES_BELOW = 5.0


def read_reconstruction(path, seed: int = 0) -> tuple[np.ndarray, int]:
    """The points of a reconstruction, mm: a point cloud, or a mesh sampled on its faces
    (:func:`colonbench.pointio.read_surface`).

    Returns
    -------
    points : (n, 3) float
    dropped : int
        Rows left out for not being finite (NaN or infinite).

    Raises
    ------
    InputError
        Missing or unreadable file, unknown type, fewer than 100 points, or
        coordinates that look like metres.
    """
    from colonbench.pointio import read_surface

    points, dropped = read_surface(path, seed)
    if len(points) < 100:
        raise InputError(f"{path}: {len(points)} points; a colon reconstruction has thousands")
    check_millimetres(points, str(path))
    return points, dropped


def check_millimetres(points: np.ndarray, what: str) -> None:
    """Refuse coordinates whose extent says metres (a colon spans hundreds of millimetres)."""
    diagonal = float(np.linalg.norm(np.ptp(points, axis=0)))
    if diagonal < METRES_BELOW:
        raise InputError(f"{what}: the points span {diagonal:.3g} units; colonbench works in millimetres and a "
                         "colon spans hundreds of them. Metres? Multiply by 1000.")


def read_trajectory(path) -> np.ndarray:
    """(k, 3) camera positions in time order, from a TUM trajectory or a plain (k, 3) array.

    TUM: one pose per line, ``timestamp tx ty tz qx qy qz qw``, ``#`` comments;
    lines are sorted by timestamp. Plain: ``.npy`` or text with three columns. Text is read by
    :func:`colonbench.pointio.read_text_table` (a header line, commas or semicolons allowed).

    Raises
    ------
    InputError
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such trajectory file")
    try:
        if path.suffix.lower() == ".npy":
            arr = np.load(path, allow_pickle=False)
        else:
            arr = read_text_table(path, columns=None, what="a row of a TUM trajectory or of x, y, z positions")
    except InputError:
        raise
    except Exception as exc:  # noqa: BLE001
        raise InputError(f"{path}: could not read a trajectory ({type(exc).__name__}: {exc})") from None
    arr = np.asarray(arr, float)
    if arr.ndim != 2 or arr.shape[1] not in (3, 8):
        raise InputError(f"{path}: a trajectory is TUM (8 columns: timestamp tx ty tz qx qy qz qw) or (k, 3) "
                         f"positions; got shape {arr.shape}")
    if arr.shape[1] == 8:
        arr = arr[np.argsort(arr[:, 0], kind="stable"), 1:4]
    if len(arr) < 2 or not np.isfinite(arr).all():
        raise InputError(f"{path}: a trajectory needs at least two finite positions")
    return arr


def check_trajectory(positions: np.ndarray, points: np.ndarray, what: str) -> None:
    """Refuse a trajectory that cannot be the one that made ``points`` (another unit, another frame).

    The camera travels inside the colon: its positions must span a comparable
    extent (a tenth to ten times the reconstruction's) and lie near the surface
    (median distance to the nearest point under 60 mm, wider than any colon).
    """
    from scipy.spatial import cKDTree

    span_t = float(np.linalg.norm(np.ptp(positions, axis=0)))
    span_r = float(np.linalg.norm(np.ptp(points, axis=0)))
    ratio = span_t / max(span_r, 1e-12)
    if not 0.1 <= ratio <= 10.0:
        raise InputError(f"{what}: the trajectory spans {span_t:.3g} units and the reconstruction {span_r:.3g} mm "
                         f"(ratio {ratio:.2g}); is the trajectory in another unit (metres)?")
    d, _ = cKDTree(points).query(positions)
    if float(np.median(d)) > 60.0:
        raise InputError(f"{what}: the camera positions lie {np.median(d):.0f} mm (median) from the "
                         "reconstruction; is the trajectory in another frame?")
