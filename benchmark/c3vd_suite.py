"""A suite from the user's C3VD / C3VDv2 download: ``colonbench suites build c3vd --from DIR``.

C3VD's licence (CC BY-NC-SA 4.0) forbids redistributing it, so colonbench ships this importer and never the data.
:func:`build` reads a download (:mod:`colonbench.video.c3vd`), and for each registered sequence

1. checks its conventions before using it: its depth frames, reprojected through the fisheye model with its poses,
   must land on its mesh (median distance at most :data:`colonbench.video.c3vd.MAX_MEDIAN_MM`) in one of the pose
   conventions tried (as written or transposed, translation in mm or m); the first that does is used and
   recorded, and a sequence where none does is refused, naming it;
2. fuses its depth frames (every ``frames_every``-th, each as five virtual pinholes covering the fisheye's
   field) into a reconstruction-like surface (:mod:`colonbench.video.c3vd_fusion`);
3. cuts its phantom into segments along the mesh's own centerline and writes their samples, truth from C3VD's
   per-face coverage (:mod:`colonbench.shards.c3vd_shards`); checks that the fused partials reach what that
   truth calls observed (:func:`colonbench.shards.c3vd_shards.video_check`: at least 95 % of the observed area
   within 1.5 mm, recorded per sequence as ``video_check``), and leaves out the sequence's ``video`` samples,
   with the figure, where they do not;

then writes the suite's lock, its per-sample signature and its registry entry
(:mod:`colonbench.benchmark.local_suites`). The suite is built in a hidden sibling folder and renamed into place
only when complete: on any error it is removed, and nothing half-built remains. Its id is the digest of the
importer's version, the build's options and every file of the download it reads, so the same download gives the
same id on any machine. C3VDv2's screening withdrawals (poses over a whole colon, no coverage map) make a second
suite, a whole-colon one (:mod:`colonbench.benchmark.c3vd_colon`); :func:`build_all` builds both.
"""

from __future__ import annotations

import hashlib
import json
import time
from pathlib import Path

import numpy as np

from colonbench.benchmark import local_suites
from colonbench.errors import ColonbenchError, InputError

#: The importer's name and version: a change that moves a built suite's data is a new version (a new id).
IMPORTER = "c3vd"
IMPORTER_VERSION = 2
NOISE_MM = (0.0, 0.5)
NOISE_SEED = 0
LICENCE = ("C3VD and C3VDv2 are licensed CC BY-NC-SA 4.0 (non-commercial, share alike): a suite built from them "
           "may not be used commercially or redistributed under other terms")
CITE = ("Bobrow, Golhar, Vijayan, Akshintala, Garcia and Durr, Colonoscopy 3D video dataset with paired depth from "
        "2D-3D registration, Medical Image Analysis 90:102956, 2023",
        "Golhar et al., C3VDv2, arXiv 2506.24074, 2025")


def sha256_of(path: Path) -> str:
    """A download file's sha256, or an error naming it."""
    h = hashlib.sha256()
    try:
        with open(path, "rb") as fh:
            for chunk in iter(lambda: fh.read(1 << 22), b""):
                h.update(chunk)
    except OSError as exc:
        raise InputError(f"{path}: unreadable ({exc})") from None
    return h.hexdigest()


def source_digests(sequences) -> dict:
    """Every file the importer reads, named ``<sequence>/<path in its folder>`` (a file outside it, the intrinsics
    or a screening withdrawal's whole-colon mesh, ``<sequence>/<file name>``), so that where the download was
    unpacked does not matter: its sha256; and per sequence the count of its files and the digest of their
    digests."""
    files, per, known = {}, {}, {}
    for seq in sequences:
        mine = {}
        for path in seq.files():
            path = Path(path)
            rel = path.relative_to(seq.folder).as_posix() if path.is_relative_to(seq.folder) else path.name
            if path not in known:           # a whole-colon mesh several withdrawals share is read once
                known[path] = sha256_of(path)
            mine[f"{seq.name}/{rel}"] = known[path]
        files.update(mine)
        per[seq.name] = {"files": len(mine), "sha256": json_digest(mine)}
    return {"files": files, "sequences": per, "digest": json_digest(files)}


def json_digest(obj) -> str:
    """The sha256 (hex) of ``obj`` as canonical JSON (sorted keys, no spaces): the digest suite ids and digests of
    digests are made of (also by :mod:`colonbench.server.hidden`).

    Parameters
    ----------
    obj : object
        Anything :func:`json.dumps` takes.

    Returns
    -------
    str
        64 hex digits.
    """
    return hashlib.sha256(json.dumps(obj, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def suite_identity(importer: str, version: int, options: dict, sequences) -> tuple[str, dict, dict, float]:
    """A built suite's id (``<importer>-<12 hex>``) from the importer, its version, its options and the digest of
    every file it reads: the same download and options give the same id. Also the identity its shards record,
    the files' digests (:func:`source_digests`) and the seconds hashing them took."""
    t0 = time.perf_counter()
    digests = source_digests(sequences)
    seconds = round(time.perf_counter() - t0, 1)
    key = json_digest({"importer": importer, "version": version, "options": options, "files": digests["files"]})
    sid = f"{importer}-{key[:12]}"
    return sid, {"manifest_name": sid, "manifest_sha256": key, "config_sha256": json_digest(options)}, digests, seconds


def build_sequence(seq, colon_id: int, out: str, settings, identity: dict, frames_every: int, width_px: int,
                   progress: bool = False) -> tuple[list, list, dict]:
    """Check, fuse and cut one sequence into ``out`` (see the module's description); its shards, the segments left
    out and what was found (convention, medians, frames fused, coverage, centerline length)."""
    import trimesh

    from colonbench.datagen.camera import SurfaceScene
    from colonbench.datagen.mesh_centerline import open_tube_centerline
    from colonbench.shards.c3vd_shards import write_sequence_shards
    from colonbench.video import c3vd
    from colonbench.video.c3vd_fusion import fuse_sequence
    from colonbench.video.fisheye import read_intrinsics

    clock = [time.perf_counter()]

    def lap(stage):
        now = time.perf_counter()
        seconds[stage] = round(seconds.get(stage, 0.0) + now - clock[0], 2)
        clock[0] = now

    seconds = {}
    v, f, observed = c3vd.read_coverage_mesh(seq.mesh)
    extent = float(np.ptp(v, axis=0).max())
    if extent < 5.0:
        raise InputError(f"{seq.mesh}: only {extent:.3g} units across; C3VD's meshes are in millimetres")
    raw = c3vd.read_poses(seq.poses)
    scene = SurfaceScene(v, f)
    areas = scene.areas
    report = {"folder": seq.folder.name, "layout": seq.layout, "mesh": seq.mesh.name, "faces": int(len(f)),
              "observed_share": float(areas[observed].sum() / areas.sum()), "poses": int(len(raw)),
              "depth_frames": len(seq.depth), "convention": None, "fused_frames": 0, "seconds": seconds}
    lap("read")
    fused = None
    if seq.depth:
        c3vd.check_frames(seq, raw)
        intr = read_intrinsics(seq.intrinsics)
        report["convention"] = c3vd.check_conventions(seq.name, raw, seq.depth, intr, scene.distance)
        lap("check")
        conv = report["convention"]
        poses = c3vd.camera_to_world(raw, conv["transposed"], conv["scale"])
        from colonbench.progress import bar as progress_bar

        bar = progress_bar(total=len(range(0, len(seq.depth), frames_every)), unit="frame", desc=f"fuse {seq.name}",
                           enabled=progress)
        try:
            fused = fuse_sequence(seq.depth, poses, intr, every=frames_every, width_px=width_px,
                                  progress=bar.update if progress else None)
        finally:
            bar.close()
        report.update(fused_frames=len(fused["frames"]), pinhole=fused["pinhole"])
        lap("fuse")
    try:
        centerline = open_tube_centerline(trimesh.Trimesh(v, f, process=False))
    except Exception as exc:  # noqa: BLE001 - whatever the mesh did to the centerline, the sequence is named
        why = str(exc) if isinstance(exc, ColonbenchError) else f"{type(exc).__name__}: {exc}"
        raise InputError(f"sequence {seq.name} ({seq.mesh}): no centerline of its mesh ({why})") from None
    report["centerline_mm"] = float(centerline.length)
    lap("centerline")
    shards, skipped, report["video_check"] = write_sequence_shards(out, seq.name, colon_id, v, f, observed, centerline,
                                                                   fused, settings, identity)
    lap("segments")
    report["samples"] = int(sum(s["samples"] for s in shards))
    return shards, skipped, report


def _run_all(sequences, tmp: Path, settings, identity, frames_every, width_px, workers, progress):
    args = [(seq, k, str(tmp), settings, identity, frames_every, width_px) for k, seq in enumerate(sequences)]
    if workers > 1 and len(sequences) > 1:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(max_workers=min(workers, len(args)),
                                 mp_context=multiprocessing.get_context("spawn")) as pool:
            return list(pool.map(build_sequence, *zip(*args)))
    return [build_sequence(*a, progress=progress) for a in args]


def _check_options(frames_every: int | None, width_px: int | None, workers: int) -> tuple[int, int]:
    """The frames step and view width to fuse at (the fusion's defaults for None), checked."""
    from colonbench.video import c3vd_fusion

    every = c3vd_fusion.EVERY if frames_every is None else frames_every
    width = c3vd_fusion.WIDTH_PX if width_px is None else width_px
    if every < 1 or width < 16 or workers < 1:
        raise InputError(f"--frames-every must be >= 1, the pinhole width >= 16 and --workers >= 1; got "
                         f"{every}, {width}, {workers}")
    return every, width


def segment_job(sequences, skipped, frames_every: int, width_px: int, workers: int, progress: bool):
    """The segment suite of a download's registered sequences: its id and its maker
    (:func:`colonbench.benchmark.local_suites.publish`)."""
    from colonbench.shards.c3vd_shards import ImportSettings

    t0 = time.perf_counter()
    settings = ImportSettings()
    options = {"frames_every": int(frames_every), "pinhole_width_px": int(width_px), "settings": settings.to_dict(),
               "noise_mm": list(NOISE_MM), "noise_seed": NOISE_SEED}
    sid, identity, digests, digest_seconds = suite_identity(IMPORTER, IMPORTER_VERSION, options, sequences)
    key = identity["manifest_sha256"]

    def make(tmp: Path) -> dict:
        results = _run_all(sequences, tmp, settings, identity, frames_every, width_px, workers, progress)
        entry = _finish(tmp, sid, key, identity, sequences, skipped, results, options, digests, t0)
        entry["digest_seconds"] = digest_seconds
        return entry

    return sid, make


def build(source, root=None, frames_every: int | None = None, width_px: int | None = None, workers: int = 1,
          intrinsics=None, progress: bool = True) -> tuple[local_suites.LocalSuite, bool]:
    """Build (or find already built) the segment suite of a C3VD download's registered sequences
    (:func:`build_all` also builds the whole-colon suite of its screening withdrawals).

    Parameters
    ----------
    source : path
        The download's folder (registered sequences at any depth; :func:`colonbench.video.c3vd.find_download`).
    root : path, optional
        The suite data root (default :func:`colonbench.benchmark.suites.default_data_root`).
    frames_every : int, optional
        Fuse every this many-th depth frame (default :data:`colonbench.video.c3vd_fusion.EVERY`).
    width_px : int, optional
        Width of each virtual pinhole the fused frames are resampled into, pixels (default
        :data:`colonbench.video.c3vd_fusion.WIDTH_PX`).
    workers : int
        Sequences built at a time (processes).
    intrinsics : path, optional
        ``camera_intrinsics.txt`` for every sequence, in place of the download's own (needed where it holds none).
    progress : bool

    Returns
    -------
    suite : LocalSuite
    built : bool
        False where it was already built (nothing was done).

    Raises
    ------
    InputError
        A file that cannot be read (named), an unknown layout, no registered sequence, a sequence whose
        conventions cannot be made to agree (named); nothing is left in the data root.
    """
    from colonbench.video.c3vd import find_download

    frames_every, width_px = _check_options(frames_every, width_px, workers)
    sequences, screening, skipped = find_download(Path(source), intrinsics)
    if not sequences:
        raise InputError(f"{source}: no registered C3VD sequence found (a folder with pose.txt and "
                         f"coverage_mesh.obj), only {len(screening)} screening withdrawal(s): colonbench suites build "
                         "c3vd builds their whole-colon suite")
    return local_suites.publish(_root(root), [segment_job(sequences, skipped, frames_every, width_px, workers,
                                                          progress)])[0]


def build_all(source, root=None, frames_every: int | None = None, width_px: int | None = None, workers: int = 1,
              intrinsics=None, progress: bool = True) -> list[tuple[local_suites.LocalSuite, bool]]:
    """Build (or find already built) every suite of a C3VD download: the segment suite of its registered
    sequences (:func:`build`) and the whole-colon suite of its screening withdrawals
    (:mod:`colonbench.benchmark.c3vd_colon`), whichever it holds, both or neither put in place.

    Parameters
    ----------
    source, root, frames_every, width_px, workers, intrinsics, progress
        As :func:`build`; ``frames_every`` is also the step between the frames whose views make a screening
        withdrawal's visibility (default :data:`colonbench.benchmark.c3vd_colon.FRAMES_EVERY`).

    Returns
    -------
    list of (LocalSuite, bool)
        The segment suite first where there is one; whether each was built (False: already built).

    Raises
    ------
    InputError
        As :func:`build`, a screening withdrawal whose trajectory does not lie inside its phantom (named), and a
        download of which no suite can be made (every withdrawal left out: the reasons); nothing is left in the
        data root.
    """
    from colonbench.benchmark import c3vd_colon
    from colonbench.video.c3vd import find_download

    fuse_every, width_px = _check_options(frames_every, width_px, workers)
    sequences, screening, skipped = find_download(Path(source), intrinsics)
    jobs = []
    if screening:    # first: a withdrawal it leaves out joins the download's skipped folders every entry lists
        view_every = c3vd_colon.FRAMES_EVERY if frames_every is None else frames_every
        jobs.append(c3vd_colon.colon_job(screening, skipped, view_every, progress))
    if sequences:
        jobs.append(segment_job(sequences, skipped, fuse_every, width_px, workers, progress))
    built = [b for b in local_suites.publish(_root(root), jobs) if b is not None]
    if not built:
        raise InputError(f"{source}: no suite can be made of the download ("
                         + "; ".join(f"{s['folder']}: {s['reason']}" for s in skipped) + ")")
    return sorted(built, key=lambda b: b[0].task != "segments")


def _root(root) -> Path:
    from colonbench.benchmark import suites

    return Path(root) if root is not None else suites.default_data_root()


def _finish(tmp: Path, sid, key, identity, sequences, skipped, results, options, digests, t0):
    """Write the lock, signature and descriptive manifest of a built suite's folder; its registry entry (to write
    last)."""
    import yaml

    from colonbench.benchmark import verification
    from colonbench.benchmark.evaluate import select
    from colonbench.benchmark.fingerprint import segments_fingerprint
    from colonbench.shards.c3vd_shards import write_lock

    shards = [s for r in results for s in r[0]]
    if not shards:
        why = "; ".join(f"{seq.name}: {r[1][0]['reason'] if r[1] else 'too short to cut'}"
                        for seq, r in zip(sequences, results))
        raise InputError(f"no segment of the download could be made ({why})")
    lock = write_lock(tmp, identity, shards)
    (tmp / "manifest.yaml").write_text(yaml.safe_dump(
        {"name": sid, "task": "segments", "description": "built by colonbench suites build c3vd from a C3VD "
         "download (not a generator manifest: it cannot be generated again without the download)",
         "importer": f"{IMPORTER} {IMPORTER_VERSION}", "options": options, "source_digest": digests["digest"]},
        sort_keys=False))
    _, picks = select(tmp, "test", None)
    sha256, records = segments_fingerprint(tmp, picks, NOISE_MM, NOISE_SEED)
    for r in records:   # the camera sample is drawn on the true surface, the video one on a fused surface
        r["cloud"] = "reconstruction" if r["hole_model"] == "video" else "surface"
    stub = local_suites.LocalSuite(IMPORTER, IMPORTER_VERSION, "", "segments", "", len(records), sha256, 0.0,
                                   noise_mm=NOISE_MM, noise_seed=NOISE_SEED, local_id=sid)
    published = verification.make(stub, lock, sha256, records)
    verification.write(published, tmp / local_suites.SIGNATURE_FILE)
    reports = {seq.name: {**digests["sequences"][seq.name], **r[2], "skipped_segments": r[1]}
               for seq, r in zip(sequences, results)}
    depth = sum(1 for r in results if (r[2].get("video_check") or {}).get("passed"))
    tests = (f"real colonoscope trajectories of C3VD: {len(sequences)} registered sequence(s) of silicone phantoms "
             f"({', '.join(seq.name for seq in sequences[:4])}{', ...' if len(sequences) > 4 else ''}) cut into "
             f"50-70 mm segments along their centerlines, truth from C3VD's per-face coverage; partials on the observed "
             f"faces (camera) and, for {depth} whose fused depth frames reach their truth, the frames fused by TSDF (video)")
    entry = {"format": local_suites.FORMAT, "format_version": local_suites.FORMAT_VERSION, "id": sid,
             "name": IMPORTER, "version": IMPORTER_VERSION, "task": "segments", "tests": tests,
             "samples": len(records), "sha256": sha256, "signature": verification.digest(published),
             "noise_mm": list(NOISE_MM), "noise_seed": NOISE_SEED,
             "build_seconds": round(time.perf_counter() - t0, 1),
             "importer": {"name": IMPORTER, "version": IMPORTER_VERSION}, "options": options,
             "source": {"digest": digests["digest"], "files": digests["files"], "sequences": reports,
                        "skipped": skipped},
             "licence": LICENCE, "cite": list(CITE)}
    return entry
