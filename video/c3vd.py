"""Reading a C3VD / C3VDv2 download: its registered sequences, coverage meshes, poses, depth frames, and the check
that they agree.

C3VD (Bobrow et al., Medical Image Analysis 2023) and C3VDv2 (Golhar et al., arXiv 2506.24074, 2025) are
colonoscope videos of silicone colon phantoms registered to the phantoms' meshes. Each registered sequence is a
folder holding (checked against the dataset's renderer, ``rendergt`` in github.com/DurrLab/C3VD):

- ``coverage_mesh.obj`` (v1 also ``outputMesh.obj``): the phantom's mesh in the world frame, mm; each face's
  texture coordinate is its coverage: ``vt 0 0`` (written first, index 1) where a pixel of some frame first hit
  the face, ``vt 1 1`` (index 2) where none did: no distance or angle limit;
- ``pose.txt``: one line per frame, 16 comma-separated numbers. The renderer writes a glm (column-major)
  camera-to-world matrix column by column, so the line read row by row is its transpose: translation in the
  last row, applied to row vectors as ``[x y z 1] @ M`` (the dataset's loader does so; C3VD issues 3 and 20).
  This module finds the convention from the data instead of trusting it (:func:`check_conventions`);
- ``depth/NNNN_depth.tiff`` (v1: ``NNNN_depth.tiff`` beside ``pose.txt``): 16-bit z depth, 0-100 mm over
  0-65535 (``value / 65535 * 100``); 0 (no surface) and 65535 (100 mm or farther) are invalid;
- ``camera_intrinsics.txt`` in the sequence's folder or a folder above it (C3VDv2: the download's root): the
  fisheye model of :mod:`colonbench.video.fisheye`.

A folder with ``pose.txt`` but no coverage mesh is a C3VDv2 screening withdrawal over a whole colon where its name
and its whole-colon mesh say so (:mod:`colonbench.video.c3vd_screening`, read by :func:`find_download`), and is
listed as skipped, with the reason, otherwise; so is every other folder of the download the importer reads nothing
from (one holding a coverage mesh or depth frames but no ``pose.txt``, say).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from colonbench.errors import InputError, listing
from colonbench.video.fisheye import Fisheye

#: Names of a sequence's coverage mesh, in order of preference.
MESH_NAMES = ("coverage_mesh.obj", "outputMesh.obj")
POSE_NAME = "pose.txt"
INTRINSICS_NAME = "camera_intrinsics.txt"
#: Depth in mm of the 16-bit value 65535.
DEPTH_RANGE_MM = 100.0
#: A sequence is used only where its depth frames, reprojected with its poses, lie on its mesh: the median
#: distance of the reprojected points to the mesh at most this, mm. C3VD's depth is rendered from that mesh (its
#: 16-bit steps are 0.0015 mm); a wrong pose convention or depth scale puts the points millimetres to centimetres
#: off.
MAX_MEDIAN_MM = 1.0
#: Frames and points per frame the check reprojects.
CHECK_FRAMES = 12
CHECK_POINTS = 2000
#: The pose conventions tried: (name, transposed, translation scale to mm). "C3VD" is the dataset's own.
CONVENTIONS = (("transposed (C3VD's: row vectors, translation in the last row), mm", True, 1.0),
               ("as written (column vectors, translation in the last column), mm", False, 1.0),
               ("transposed, translation in metres", True, 1000.0),
               ("as written, translation in metres", False, 1000.0))
_DEPTH = re.compile(r"^(\d+)_depth\.tiff?$")
#: Names of a packed download given in place of its folder.
ARCHIVES = (".zip", ".tar", ".tar.gz", ".tgz", ".7z", ".rar")


@dataclass
class Sequence:
    """One registered sequence of a download.

    Attributes
    ----------
    name : str
        Its folder's name (``c1_cecum_t1_v1``).
    folder, mesh, poses : Path
    depth : list of Path
        Frame ``k``'s depth file at ``depth[k]`` (empty where the sequence has none).
    intrinsics : Path or None
    layout : str
        ``v2`` (depth frames in ``depth/``) or ``v1`` (beside ``pose.txt``).
    """

    name: str
    folder: Path
    mesh: Path
    poses: Path
    depth: list = field(default_factory=list)
    intrinsics: Path | None = None
    layout: str = "v2"

    def files(self) -> list[Path]:
        """Every file of the sequence the importer reads, in a fixed order."""
        return [self.mesh, self.poses] + ([self.intrinsics] if self.intrinsics and self.depth else []) + self.depth


def _depth_frames(folder: Path) -> tuple[list[Path], str]:
    for where, layout in ((folder / "depth", "v2"), (folder, "v1")):
        if where.is_dir():
            found = {int(m.group(1)): p for p in where.iterdir() if (m := _DEPTH.match(p.name))}
            if found:
                missing = sorted(set(range(max(found) + 1)) - set(found))
                if missing:
                    raise InputError(f"{where / f'{missing[0]:04d}_depth.tiff'}: missing (frames 0-{max(found)} have "
                                     f"depth files but {len(missing)} do not); re-extract the sequence")
                return [found[k] for k in sorted(found)], layout
    return [], "v2"


def _intrinsics_for(folder: Path, root: Path, given) -> Path | None:
    if given is not None:
        return Path(given)
    for where in [folder, *folder.parents]:
        if (where / INTRINSICS_NAME).is_file():
            return where / INTRINSICS_NAME
        if where == root:
            break
    return None


def _walk(root: Path, intrinsics) -> tuple[list[Sequence], list[Path]]:
    """The registered sequences under a download, and the folders holding ``pose.txt`` but no coverage mesh."""
    if root.is_file():
        packed = root.name.lower().endswith(ARCHIVES)
        raise InputError(f"{root}: a file, not a folder; "
                         + ("unzip it first (C3VD ships each sequence as a .zip) and give --from the folder it "
                            "unpacks into" if packed else "--from takes the folder the download was unpacked into"))
    if not root.is_dir():
        raise InputError(f"{root}: no such folder (the C3VD download)")
    sequences, bare = [], []
    for pose in sorted(root.rglob(POSE_NAME)):
        folder = pose.parent
        mesh = next((folder / n for n in MESH_NAMES if (folder / n).is_file()), None)
        if mesh is None:
            bare.append(folder)
            continue
        depth, layout = _depth_frames(folder)
        intr = _intrinsics_for(folder, root, intrinsics)
        if depth and intr is None:
            raise InputError(f"{folder}: depth frames but no {INTRINSICS_NAME} in it or a folder above it up to "
                             f"{root}; give the camera's intrinsics file with --intrinsics")
        sequences.append(Sequence(folder.name, folder, mesh, pose, depth, intr, layout))
    return sequences, bare


def _no_sequence(root: Path, skipped: list, what: str) -> InputError:
    zips = sorted(p.name for p in root.rglob("*.zip"))
    hint = (f"; it holds {len(zips)} .zip file(s) ({listing(zips)}): unzip them first" if zips else
            f"; a registered sequence is a folder with {POSE_NAME} and {MESH_NAMES[0]}")
    named = listing([f"{s['folder']} ({s['reason']})" for s in skipped], most=3)
    return InputError(f"{root}: no {what} found" + hint
                      + (f" ({len(skipped)} folder(s) skipped: {named})" if skipped else ""))


def _holds(root: Path, folder: Path) -> str:
    """Why a folder the importer reads nothing from is skipped: what in it looks like a sequence's, if anything."""
    import os

    for here, dirs, files in os.walk(folder):
        dirs[:] = sorted(d for d in dirs if not d.startswith("."))
        rel = Path(here).relative_to(root).as_posix()
        mesh = next((n for n in MESH_NAMES if n in files), None)
        if mesh is not None:
            return (f"{rel}/{mesh}, but no {POSE_NAME} beside it: not a registered sequence (is its {POSE_NAME} "
                    "missing from the download?)")
        if any(_DEPTH.match(n) for n in files):
            return f"depth frames ({rel}), but no {POSE_NAME}: not a sequence"
    return f"no {POSE_NAME} in it or below: not a C3VD sequence, nothing in it is read"


def _unread(root: Path, sequences: list, bare: list, screening: list) -> list[dict]:
    """The download's folders the importer reads nothing from, each the topmost such (hidden ones aside), with the
    reason: neither a sequence (nor in one) nor holding one, nor holding a screening withdrawal's mesh."""
    inside = {s.folder for s in sequences} | set(bare)
    keep = set()
    for folder in inside | {Path(s.mesh).parent for s in screening}:
        keep.update(p for p in (folder, *folder.parents) if p.is_relative_to(root))
    out = []

    def visit(folder: Path) -> None:
        for child in sorted(p for p in folder.iterdir() if p.is_dir() and not p.name.startswith(".")):
            if child in inside:
                continue
            if child in keep:
                visit(child)
            else:
                out.append({"folder": child.relative_to(root).as_posix(), "reason": _holds(root, child)})

    if root not in inside:
        visit(root)
    return out


def find_download(root, intrinsics=None) -> tuple[list[Sequence], list, list[dict]]:
    """The registered sequences and the screening withdrawals under a download's folder, and the folders skipped
    with the reason.

    Parameters
    ----------
    root : path
        The download (``--from``); searched at any depth.
    intrinsics : path, optional
        The camera's ``camera_intrinsics.txt`` for every sequence, in place of the download's own (needed where it
        holds none near its sequences).

    Returns
    -------
    sequences : list of Sequence
    screening : list of :class:`colonbench.video.c3vd_screening.Screening`
    skipped : list of dict
        ``folder`` (relative to ``root``) and ``reason``: folders with ``pose.txt`` that are neither a registered
        sequence nor a screening withdrawal, then every other folder the importer reads nothing from (the topmost
        of each branch; a sequence's own folders, such as ``rgb/``, and hidden ones are not listed).

    Raises
    ------
    InputError
        A file, not a folder (a zip: unzip it first); no such folder; neither a registered sequence nor a
        screening withdrawal (the message says what was found, and names the folders skipped); a sequence with
        depth frames missing in the middle, or with no camera intrinsics for its depth frames; two sequences of one
        name; a screening withdrawal with several candidate meshes.
    """
    from colonbench.video.c3vd_screening import find_screening

    root = Path(root)
    sequences, bare = _walk(root, intrinsics)
    screening, skipped = find_screening(root, bare, {s.folder for s in sequences})
    skipped += _unread(root, sequences, bare, screening)
    names = [s.name for s in sequences] + [s.name for s in screening]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise InputError(f"{root}: two sequences are named {twice[0]!r}; give a folder holding each sequence once")
    if not sequences and not screening:
        raise _no_sequence(root, skipped, "registered C3VD sequence or screening withdrawal")
    return sequences, screening, skipped


def find_sequences(root, intrinsics=None) -> tuple[list[Sequence], list[dict]]:
    """The registered sequences under a download's folder, and the folders skipped with the reason (screening
    withdrawals among them: :func:`find_download` finds those).

    Raises
    ------
    InputError
        As :func:`find_download`, and where the download holds no registered sequence.
    """
    root = Path(root)
    sequences, bare = _walk(root, intrinsics)
    skipped = [{"folder": str(f.relative_to(root)), "reason": "pose.txt without a coverage mesh: not a registered "
                "sequence (a screening withdrawal goes into the whole-colon suite: colonbench suites build c3vd)"}
               for f in bare]
    names = [s.name for s in sequences]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise InputError(f"{root}: two sequences are named {twice[0]!r}; give a folder holding each sequence once")
    if not sequences:
        raise _no_sequence(root, skipped, "registered C3VD sequence")
    return sequences, skipped


def read_coverage_mesh(path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A C3VD coverage mesh: vertices (n, 3) float mm, triangles (m, 3) int, observed (m,) bool.

    A face is observed when its texture coordinate is ``(0, 0)`` and unobserved when it is ``(1, 1)``, the two
    coordinates C3VD writes.

    Raises
    ------
    InputError
        Naming the file (and the line): unreadable, not triangles, a face without a texture index (a mesh with
        no coverage map), or texture coordinates other than C3VD's two.
    """
    path = Path(path)
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: unreadable ({exc})") from None
    verts, tex, faces, ftex = [], [], [], []
    for no, line in enumerate(text.splitlines(), 1):
        if line.startswith("v "):
            verts.append(line[2:])
        elif line.startswith("vt "):
            tex.append(line[3:])
        elif line.startswith("f "):
            corners = line.split()[1:]
            if len(corners) != 3:
                raise InputError(f"{path}, line {no}: a face of {len(corners)} corners; C3VD's meshes are triangles")
            parts = [c.split("/") for c in corners]
            if any(len(p) < 2 or not p[1] for p in parts):
                raise InputError(f"{path}, line {no}: a face without a texture index; C3VD's coverage mesh gives "
                                 "each face's coverage as its vt (1 observed, 2 unobserved): is this a coverage mesh?")
            faces.append([p[0] for p in parts])
            ftex.append([p[1] for p in parts])
    try:
        v = np.array(" ".join(verts).split(), float).reshape(-1, 3) if verts else np.zeros((0, 3))
        t = np.array([row.split()[:2] for row in tex], float).reshape(-1, 2)
        f = np.array(faces, np.int64).reshape(-1, 3)
        ft = np.array(ftex, np.int64).reshape(-1, 3)
    except ValueError as exc:
        raise InputError(f"{path}: not a readable OBJ mesh ({exc})") from None
    if len(f) == 0 or len(v) == 0:
        raise InputError(f"{path}: holds no triangles")
    f = np.where(f < 0, f + len(v), f - 1)
    ft = np.where(ft < 0, ft + len(t), ft - 1)
    if f.min() < 0 or f.max() >= len(v) or ft.min() < 0 or ft.max() >= len(t):
        raise InputError(f"{path}: a face names a vertex or texture coordinate the file does not have")
    if not np.isfinite(v).all():
        raise InputError(f"{path}: vertices with NaN or infinite coordinates")
    if (ft != ft[:, :1]).any():
        k = int(np.flatnonzero((ft != ft[:, :1]).any(axis=1))[0])
        raise InputError(f"{path}: face {k + 1} has different texture coordinates at its corners; a coverage mesh "
                         "gives one per face")
    coords = t[ft[:, 0]]
    seen, unseen = (coords == 0).all(axis=1), (coords == 1).all(axis=1)
    if not (seen | unseen).all():
        k = int(np.flatnonzero(~(seen | unseen))[0])
        raise InputError(f"{path}: face {k + 1}'s texture coordinate is {tuple(coords[k])}; a C3VD coverage mesh "
                         "uses (0, 0) for observed faces and (1, 1) for unobserved ones")
    return v, f, seen


def read_poses(path) -> np.ndarray:
    """``pose.txt`` as written: (n, 4, 4), each line's 16 numbers read row by row (convention not applied).

    Raises
    ------
    InputError
        Naming the file and line: not 16 numbers, or not finite.
    """
    path = Path(path)
    try:
        lines = [ln for ln in path.read_text().splitlines() if ln.strip()]
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: unreadable ({exc})") from None
    out = np.zeros((len(lines), 16))
    for k, line in enumerate(lines):
        try:
            row = np.array([float(x) for x in re.split(r"[,\s]+", line.strip())])
        except ValueError:
            row = np.zeros(0)
        if row.size != 16 or not np.isfinite(row).all():
            raise InputError(f"{path}, pose {k + 1}: not 16 finite numbers (C3VD writes a flattened 4 x 4 matrix "
                             "per line)")
        out[k] = row
    if len(out) == 0:
        raise InputError(f"{path}: no poses")
    return out.reshape(-1, 4, 4)


def read_depth(path, intrinsics: Fisheye | None = None) -> np.ndarray:
    """A C3VD depth frame as z in mm, float32 (height, width); 0 where invalid (0 or 65535 stored).

    Raises
    ------
    InputError
        Naming the file: unreadable, not a 16-bit single-channel image, or not the intrinsics' size.
    """
    import tifffile

    path = Path(path)
    try:
        raw = tifffile.imread(path)
    except Exception as exc:  # noqa: BLE001 - tifffile raises many kinds on a bad file
        raise InputError(f"{path}: not a readable TIFF ({type(exc).__name__}: {exc})") from None
    if raw.dtype != np.uint16 or raw.ndim != 2:
        raise InputError(f"{path}: a {raw.dtype} image of shape {raw.shape}; C3VD's depth frames are 16-bit, one "
                         "channel")
    if intrinsics is not None and raw.shape != (intrinsics.height, intrinsics.width):
        raise InputError(f"{path}: {raw.shape[1]} x {raw.shape[0]} pixels; the camera's intrinsics are for "
                         f"{intrinsics.width} x {intrinsics.height}")
    valid = (raw > 0) & (raw < 65535)
    return np.where(valid, raw.astype(np.float32) * np.float32(DEPTH_RANGE_MM / 65535.0), np.float32(0))


def camera_to_world(raw: np.ndarray, transposed: bool, scale: float = 1.0) -> np.ndarray:
    """Poses as read (:func:`read_poses`) in one convention, as column-vector camera-to-world matrices in mm;
    (n, 4, 4)."""
    m = np.swapaxes(raw, 1, 2).copy() if transposed else np.array(raw, float)
    m[:, :3, 3] *= scale
    return m


def _rigid(m: np.ndarray) -> bool:
    bottom = np.abs(m[:, 3] - [0, 0, 0, 1]).max(axis=1) < 1e-6
    r = m[:, :3, :3]
    ortho = np.abs(np.einsum("nij,nkj->nik", r, r) - np.eye(3)).max(axis=(1, 2)) < 1e-3
    return bool((bottom & ortho).all())


def check_conventions(name: str, raw: np.ndarray, depth: list, intrinsics: Fisheye, distance,
                      frames: int = CHECK_FRAMES, points: int = CHECK_POINTS, limit_mm: float = MAX_MEDIAN_MM) -> dict:
    """Which pose convention puts a sequence's reprojected depth frames on its mesh; refuse where none does.

    Parameters
    ----------
    name : str
        The sequence, for messages.
    raw : (n, 4, 4) float
        Poses as read.
    depth : list of Path
        Depth frame files, frame by frame.
    intrinsics : Fisheye
    distance : callable
        (k, 3) world points, mm -> (k,) distance to the mesh, mm.
    frames, points : int
        Frames checked (spread evenly) and points per frame.
    limit_mm : float
        The largest median distance accepted.

    Returns
    -------
    dict
        ``convention`` (name), ``transposed``, ``scale``, ``median_mm`` (the chosen one's), ``medians`` (every
        convention's; None where the matrices are not rigid), ``frames`` (checked), ``points``.

    Raises
    ------
    InputError
        No convention brings the median under ``limit_mm``: the message names the sequence and every median.
    """
    picks = np.unique(np.linspace(0, len(depth) - 1, min(frames, len(depth))).round().astype(int))
    step = max(1, int(np.sqrt(intrinsics.width * intrinsics.height / points)))
    cam = []
    for k in picks:
        pts, _ = intrinsics.points(read_depth(depth[k], intrinsics), step)
        cam.append(pts)
    if sum(len(p) for p in cam) == 0:
        raise InputError(f"sequence {name}: its checked depth frames ({listing([depth[k].name for k in picks], 3)}) "
                         "hold no valid pixel; nothing to check the poses against")
    medians, best = {}, None
    for label, transposed, scale in CONVENTIONS:
        poses = camera_to_world(raw[picks], transposed, scale)
        if not _rigid(poses):
            medians[label] = None
            continue
        world = np.concatenate([p @ m[:3, :3].T + m[:3, 3] for p, m in zip(cam, poses)])
        medians[label] = float(np.median(distance(world)))
        if best is None or medians[label] < medians[best[0]]:
            best = (label, transposed, scale)
    if best is None or medians[best[0]] > limit_mm:
        found = "; ".join(f"{k}: {'not rigid' if v is None else f'{v:.2f} mm'}" for k, v in medians.items())
        raise InputError(f"sequence {name}: its depth frames reprojected with its poses do not land on its mesh in any "
                         f"pose convention (median distance to the mesh, {limit_mm:g} mm allowed: {found}); check that "
                         "pose.txt, the depth frames and the coverage mesh belong together and that the depth is "
                         "C3VD's 0-100 mm over 0-65535")
    return {"convention": best[0], "transposed": best[1], "scale": best[2], "median_mm": medians[best[0]],
            "medians": medians, "frames": [int(k) for k in picks], "points": int(sum(len(p) for p in cam))}


def check_frames(seq: Sequence, poses: np.ndarray) -> None:
    """Refuse a sequence whose depth frames and poses do not pair one to one, naming the first missing file."""
    if seq.depth and len(seq.depth) != len(poses):
        if len(seq.depth) < len(poses):
            where = seq.depth[0].parent / f"{len(seq.depth):04d}_depth.tiff"
            raise InputError(f"{where}: missing ({seq.poses} has {len(poses)} poses, the sequence "
                             f"{len(seq.depth)} depth frames)")
        raise InputError(f"{seq.poses}: {len(poses)} poses for {len(seq.depth)} depth frames; C3VD has one pose per "
                         "frame")
