"""C3VDv2's simulated screening withdrawals: whole-colon trajectories over whole-colon phantom meshes, found in a
download, checked against their mesh, and seen with the project's own camera.

C3VDv2's pages (durrlab.github.io/C3VD, its Dataverse listing) describe the screening videos as full-colon
withdrawals by a gastroenterologist, shipped as one zip per video, ``cN_full_tK_v1.zip`` (C3VD v1's renamed
``c0_full_tK_v1``, formerly ``screening_tK``), holding the RGB frames and ``pose.txt`` only: no depth frames and
no coverage map. Their phantom's mesh is a separate download (C3VD v1 lists ``c0_full_model.zip``). What this
module assumes of that layout, where the pages do not say:

- a screening sequence is a folder named ``cN_full_...`` (or ``screening...``, C3VD v1's old name, colon ``c0``)
  holding ``pose.txt``, no coverage mesh and no depth frames;
- ``pose.txt`` is read as the registered sequences' (16 numbers a line, :func:`colonbench.video.c3vd.read_poses`),
  camera-to-world, mm; its convention is checked from the data (:func:`check_trajectory`);
- its whole-colon mesh is the one mesh file (``.obj``, ``.ply``, ``.stl``) in the sequence's own folder (the
  C3VD renderer's ``model.obj``), else the one mesh file under the download whose path has a part starting with
  ``cN_full`` (``c1_full_model/...``, ``c1_full.obj``): the colon's full model, unzipped anywhere. Several
  candidates are refused, naming them; none leaves the sequence skipped, with the reason.

The trajectory is checked instead of the depth frames a registered sequence has (:func:`check_trajectory`): in
the pose convention used, the camera centres must lie inside the phantom's lumen. What the camera saw is the
project's own visibility (:func:`trajectory_visibility`, :func:`colonbench.datagen.camera.visible_faces`, as the
whole-colon reconstructions' camera model): a circular field of view, a distance cap and a near limit; C3VD's own
coverage maps have neither a distance nor an angle limit.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from colonbench.errors import InputError, listing
from colonbench.video.c3vd import CONVENTIONS, _rigid, camera_to_world

#: A screening sequence's folder name: ``cN_full...`` (its colon ``cN``) or C3VD v1's ``screening...`` (``c0``).
SCREENING = re.compile(r"^(?:(c\d+)_full(?:_.*)?|screening(?:_.*)?)$", re.IGNORECASE)
#: The whole-colon mesh files read.
MESH_SUFFIXES = (".obj", ".ply", ".stl")
#: The trajectory check: at least this share of the camera centres inside the phantom's capped mesh or within
#: :data:`WALL_MM` of its wall (a scope's lens touches the wall; C3VD's registration error is about 0.3 mm) ...
MIN_INSIDE = 0.9
WALL_MM = 2.0
#: ... and the centres spread across at least this share of the phantom's extent (bounding-box diagonals): a
#: whole-colon withdrawal crosses the colon, a trajectory in metres read as mm is a thousandth of it.
MIN_SPAN = 0.25
#: The camera's visibility: the whole-colon reconstructions' field of view (a circular cone, full angle), C3VD's
#: depth range as the distance cap (its depth frames end at 100 mm) and their near limit.
FOV_DEG = 140.0
REACH_MM = 100.0
NEAR_MM = 2.0


@dataclass
class Screening:
    """One screening withdrawal of a download.

    Attributes
    ----------
    name : str
        Its folder's name (``c1_full_t1_v1``).
    folder, mesh, poses : Path
        ``mesh`` is its whole-colon phantom's mesh, in its folder or elsewhere in the download.
    colon : str
        The colon named (``c1``), or ``""``.
    """

    name: str
    folder: Path
    mesh: Path
    poses: Path
    colon: str = ""

    def files(self) -> list[Path]:
        """Every file of the sequence the importer reads, in a fixed order."""
        return [self.mesh, self.poses]


def colon_of(name: str) -> str | None:
    """The colon a screening sequence's name names (``c1_full_t1_v1`` -> ``c1``, ``screening_t1`` -> ``c0``), or
    None where the name is not a screening sequence's."""
    m = SCREENING.match(name)
    if m is None:
        return None
    return (m.group(1) or "c0").lower()


def _meshes_in(folder: Path) -> list[Path]:
    return sorted(p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in MESH_SUFFIXES)


def find_screening(root: Path, folders: list[Path], taken: set) -> tuple[list[Screening], list[dict]]:
    """The screening sequences among folders holding ``pose.txt`` but no coverage mesh, and the rest skipped.

    Parameters
    ----------
    root : Path
        The download.
    folders : list of Path
        Folders with ``pose.txt``, no coverage mesh.
    taken : set of Path
        Folders of registered sequences (their meshes are never a whole-colon mesh).

    Raises
    ------
    InputError
        A screening sequence with several candidate whole-colon meshes (the message names them).
    """
    from colonbench.video.c3vd import _depth_frames

    found, skipped, models = [], [], None
    for folder in folders:
        rel = str(folder.relative_to(root))
        colon = colon_of(folder.name)
        if colon is None:
            skipped.append({"folder": rel, "reason": "pose.txt without a coverage mesh, and not named as a screening "
                            "withdrawal (cN_full_...): a deformation video, say; not imported"})
            continue
        if _depth_frames(folder)[0]:
            skipped.append({"folder": rel, "reason": "depth frames but no coverage mesh: neither a registered "
                            "sequence nor a screening withdrawal"})
            continue
        own = _meshes_in(folder)
        if not own:
            if models is None:   # every mesh file outside a folder with pose.txt, looked for once
                models = sorted(p for p in root.rglob("*") if p.suffix.lower() in MESH_SUFFIXES and p.is_file()
                                and not (p.parent / "pose.txt").is_file() and p.parent not in taken)
            key = f"{colon}_full"
            own = [p for p in models if any(part.lower().startswith(key)
                                            for part in p.relative_to(root).with_suffix("").parts)]
        if len(own) > 1:
            raise InputError(f"{folder}: a screening withdrawal with {len(own)} candidate whole-colon meshes "
                             f"({listing(p.relative_to(root) for p in own)}); keep one")
        if not own:
            skipped.append({"folder": rel, "reason": f"a screening withdrawal (pose.txt, no coverage mesh) without its "
                            f"whole-colon mesh: put the colon's full model ({colon}_full_model/..., or one mesh file "
                            "in the sequence's folder) in the download"})
            continue
        found.append(Screening(folder.name, folder, own[0], folder / "pose.txt", colon))
    return found, skipped


def read_mesh(path) -> tuple[np.ndarray, np.ndarray]:
    """A whole-colon mesh: vertices (n, 3) float mm, triangles (m, 3) int. OBJ is read here (``v`` and ``f``
    lines, polygons as fans, texture and normal indices ignored); PLY and STL by trimesh (vertices merged).

    Raises
    ------
    InputError
        Naming the file: unreadable, no triangles, an index out of range, a non-finite vertex.
    """
    path = Path(path)
    if path.suffix.lower() == ".obj":
        try:
            text = path.read_text()
        except (OSError, UnicodeDecodeError) as exc:
            raise InputError(f"{path}: unreadable ({exc})") from None
        verts, faces = [], []
        for no, line in enumerate(text.splitlines(), 1):
            if line.startswith("v "):
                verts.append(line[2:])
            elif line.startswith("f "):
                corners = [c.split("/")[0] for c in line.split()[1:]]
                if len(corners) < 3:
                    raise InputError(f"{path}, line {no}: a face of {len(corners)} corners")
                faces += [[corners[0], corners[k], corners[k + 1]] for k in range(1, len(corners) - 1)]
        try:
            v = np.array([row.split()[:3] for row in verts], float).reshape(-1, 3)
            f = np.array(faces, np.int64).reshape(-1, 3)
        except ValueError as exc:
            raise InputError(f"{path}: not a readable OBJ mesh ({exc})") from None
        f = np.where(f < 0, f + len(v), f - 1)
    else:
        import trimesh

        try:
            mesh = trimesh.load(path, force="mesh", process=True)
        except Exception as exc:  # noqa: BLE001 - trimesh raises many kinds on a bad file
            raise InputError(f"{path}: not a readable mesh ({type(exc).__name__}: {exc})") from None
        v, f = np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64)
    if len(f) == 0 or len(v) == 0:
        raise InputError(f"{path}: holds no triangles")
    if f.min() < 0 or f.max() >= len(v):
        raise InputError(f"{path}: a face names a vertex the file does not have")
    if not np.isfinite(v).all():
        raise InputError(f"{path}: vertices with NaN or infinite coordinates")
    return v, f


def check_trajectory(name: str, raw: np.ndarray, inside, extent_mm: float, min_inside: float = MIN_INSIDE,
                     min_span: float = MIN_SPAN) -> dict:
    """Which pose convention puts a screening sequence's camera centres inside its phantom's lumen; refuse where
    none does.

    Parameters
    ----------
    name : str
        The sequence, for messages.
    raw : (n, 4, 4) float
        Poses as read (:func:`colonbench.video.c3vd.read_poses`).
    inside : callable
        (k, 3) world points, mm -> (k,) bool: inside the capped mesh or within :data:`WALL_MM` of its wall.
    extent_mm : float
        The phantom's bounding-box diagonal, mm.
    min_inside, min_span : float
        The share of centres inside and the span (the centres' bounding-box diagonal over ``extent_mm``) needed.

    Returns
    -------
    dict
        ``convention``, ``transposed``, ``scale``, ``inside_share`` and ``span`` (the chosen one's), ``shares``
        and ``spans`` (every convention's; None where its matrices are not rigid).

    Raises
    ------
    InputError
        No convention has ``min_inside`` of its centres inside and a span of ``min_span``: the message names the
        sequence and every convention's share and span.
    """
    shares, spans, best = {}, {}, None
    for label, transposed, scale in CONVENTIONS:
        poses = camera_to_world(raw, transposed, scale)
        if not _rigid(poses):
            shares[label] = spans[label] = None
            continue
        centres = poses[:, :3, 3]
        shares[label] = float(np.mean(inside(centres)))
        spans[label] = float(np.linalg.norm(np.ptp(centres, axis=0)) / extent_mm)
        if shares[label] >= min_inside and spans[label] >= min_span and (best is None or
                                                                          shares[label] > shares[best[0]]):
            best = (label, transposed, scale)
    if best is None:
        found = "; ".join(f"{k}: not rigid" if v is None else f"{k}: {v:.1%} inside, span {spans[k]:.3g}"
                          for k, v in shares.items())
        raise InputError(f"sequence {name}: its camera centres do not lie inside its phantom's lumen in any pose "
                         f"convention ({min_inside:.0%} inside the capped mesh or within {WALL_MM:g} mm of its wall "
                         f"and a trajectory across {min_span:.0%} of the phantom needed: {found}); check that "
                         "pose.txt and the whole-colon mesh belong together")
    return {"convention": best[0], "transposed": best[1], "scale": best[2], "inside_share": shares[best[0]],
            "span": spans[best[0]], "shares": shares, "spans": spans}


def lumen_test(vertices, faces, capped, scene=None):
    """The ``inside`` of :func:`check_trajectory`: a point is inside where the capped mesh's ray parity says so,
    or within :data:`WALL_MM` of the mesh's wall.

    Parameters
    ----------
    vertices, faces
        The phantom's mesh.
    capped : trimesh.Trimesh
        It with its open ends closed (:func:`colonbench.datagen.mesh_centerline.cap_open_ends`).
    scene : SurfaceScene, optional
        The phantom's scene, when the caller has one.
    """
    from colonbench.datagen.camera import SurfaceScene

    wall = scene if scene is not None else SurfaceScene(vertices, faces)
    closed = SurfaceScene(capped.vertices, capped.faces)
    return lambda p: closed.occupancy(p, nsamples=3) | (wall.distance(p) <= WALL_MM)


def trajectory_visibility(scene, poses, every: int = 5, fov_deg: float = FOV_DEG, reach_mm: float = REACH_MM,
                          near_mm: float = NEAR_MM, chunk: int = 16, progress=None) -> tuple[np.ndarray, np.ndarray]:
    """The faces a camera sees along a trajectory, by the project's visibility
    (:func:`colonbench.datagen.camera.visible_faces`).

    Each used frame is a view from the camera's centre along its optical axis (the camera's +z, C3VD's and
    OpenCV's axes) with a circular field of ``fov_deg`` (full angle), seeing faces whose centroid lies between
    ``near_mm`` and ``reach_mm`` and is not hidden. The views are taken in chunks of ``chunk`` frames, each
    testing only the faces within reach of the chunk and not yet seen: the same union as every view at once.

    Parameters
    ----------
    scene : SurfaceScene
        The phantom.
    poses : (n, 4, 4) float
        Camera-to-world, column vectors, mm (the convention found applied).
    every : int
        Every ``every``-th frame is a view, from frame 0.
    progress : callable, optional
        Called with the frames done after each chunk.

    Returns
    -------
    observed : (m,) bool
    frames : (k,) int
        The frames used.
    """
    from scipy.spatial import cKDTree

    from colonbench.datagen.camera import Poses, visible_faces

    poses = np.asarray(poses, float)
    frames = np.arange(0, len(poses), max(int(every), 1))
    pos = poses[frames, :3, 3]
    axis = poses[frames, :3, 2] / np.linalg.norm(poses[frames, :3, 2], axis=1, keepdims=True)
    tree = cKDTree(scene.centroids)
    seen = np.zeros(len(scene.faces), bool)
    for k in range(0, len(frames), chunk):
        p = pos[k:k + chunk]
        centre = p.mean(axis=0)
        cand = np.asarray(tree.query_ball_point(centre, reach_mm + np.linalg.norm(p - centre, axis=1).max() + 1e-6),
                          np.int64)
        cand = np.sort(cand[~seen[cand]])
        if len(cand):
            views = Poses(p, axis[k:k + chunk], np.full(len(p), float(reach_mm)), np.zeros(len(p)))
            seen |= visible_faces(scene, views, fov_deg, near_mm=near_mm, candidates=cand)
        if progress is not None:
            progress(len(p))
    return seen, frames
