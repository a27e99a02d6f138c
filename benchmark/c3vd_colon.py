"""The whole-colon suite of a C3VD download: its screening withdrawals, seen along their real trajectories with the
project's own camera, mapped and scored as ``colon-v1`` is (``colonbench suites build c3vd --from DIR``).

C3VDv2's screening withdrawals come with camera poses over a whole-colon phantom and nothing else: no depth, no
coverage map (:mod:`colonbench.video.c3vd_screening`). For each whole-colon phantom mesh of the download (one
whole-colon shard, :mod:`colonbench.shards.colonshard`; its withdrawals are its samples, in name order):

1. the mesh is read, its open ends capped, and its centerline is the project's line of the capped lumen
   (:func:`colonbench.datagen.mesh_centerline.compute_centerline`, as the segment suite's phantoms), arc length 0
   at the end nearer to where the withdrawals start;
2. each withdrawal's pose convention is the one that puts its camera centres inside the phantom's lumen
   (:func:`colonbench.video.c3vd_screening.check_trajectory`; a sequence where none does is refused, naming it);
3. what it saw is the project's visibility along its real trajectory, every ``frames_every``-th frame a view
   (:func:`colonbench.video.c3vd_screening.trajectory_visibility`: a 140 degree cone, 2-100 mm): exact per-face
   truth for that camera model;
4. its whole partial reconstruction is drawn on the observed faces (2 points per mm^2, the whole-colon
   reconstructions' density), and its trajectory is every frame's camera centre in time order (what the map is
   given as the scope's path);
5. a withdrawal the map cannot map is left out, with the reason, among the download's skipped folders: where the
   map's own centerline of its partial and trajectory (:func:`colonbench.mapping.colonmap.map_centerline`) is a
   single segment by the map's rule (:func:`colonbench.mapping.colonmap.single_segment`, the protocol's segment
   length), every method would fail it. A colon left without a withdrawal has no shard, a download left without
   one no whole-colon suite.

The suite's protocol is ``colon-v1``'s: its noise levels and seed, tracks (context margins) and segment length, so
``colonbench benchmark`` / ``evaluate --task colon`` map and score it as they do ``colon-v1``. Its id is
``c3vd-colon-<12 hex>``, the digest of this importer's version, the build's options and the withdrawals' files;
it is built beside the segment suite of the same download, atomically with it
(:func:`colonbench.benchmark.c3vd_suite.build_all`).
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from colonbench.errors import ColonbenchError, InputError
from colonbench.video.c3vd_screening import FOV_DEG, MIN_INSIDE, MIN_SPAN, NEAR_MM, REACH_MM, WALL_MM

IMPORTER = "c3vd-colon"
IMPORTER_VERSION = 2
#: The default step between the frames whose views make a withdrawal's visibility.
FRAMES_EVERY = 5


@dataclass(frozen=True)
class ScreeningSettings:
    """How a screening withdrawal becomes a whole partial reconstruction (recorded in the suite's options)."""

    fov_deg: float = FOV_DEG
    reach_mm: float = REACH_MM
    near_mm: float = NEAR_MM
    point_density: float = 2.0
    min_inside: float = MIN_INSIDE
    wall_mm: float = WALL_MM
    min_span: float = MIN_SPAN
    seed: int = 0

    def to_dict(self) -> dict:
        return asdict(self)


def protocol():
    """The suite whose protocol the whole-colon suite takes (noise, tracks, segment length): ``colon-v1``."""
    from colonbench.benchmark import suites

    return suites.get("colon-v1")


def groups(screening) -> list[tuple[str, list]]:
    """The withdrawals by whole-colon mesh: ``[(colon name, [Screening, ...]), ...]`` in the order of their first
    names; a colon is named ``<colon>_full`` (``c1_full``), or with its mesh's stem where two meshes share that."""
    by_mesh: dict = {}
    for s in sorted(screening, key=lambda s: s.name):
        by_mesh.setdefault(Path(s.mesh).resolve(), []).append(s)
    keys = [f"{g[0].colon}_full" for g in by_mesh.values()]
    return [(k if keys.count(k) == 1 else f"{k}-{Path(g[0].mesh).stem}", g) for k, g in zip(keys, by_mesh.values())]


def _mesh_and_centerline(name: str, seqs: list):
    import trimesh

    from colonbench.datagen.mesh_centerline import cap_open_ends, compute_centerline
    from colonbench.video.c3vd_screening import read_mesh

    mesh = Path(seqs[0].mesh)
    v, f = read_mesh(mesh)
    extent = float(np.ptp(v, axis=0).max())
    if extent < 5.0:
        raise InputError(f"{mesh}: only {extent:.3g} units across; C3VD's meshes are in millimetres")
    who = f"colon {name} ({mesh}, the mesh of {', '.join(s.name for s in seqs)})"
    try:
        capped = cap_open_ends(trimesh.Trimesh(v, f, process=False))
        centerline = compute_centerline(capped, require_closed=False)
    except Exception as exc:  # noqa: BLE001 - whatever the mesh did to the centerline, the colon is named
        why = str(exc) if isinstance(exc, ColonbenchError) else f"{type(exc).__name__}: {exc}"
        raise InputError(f"{who}: no centerline of its mesh ({why})") from None
    return v, f, capped, centerline


def build_colon(name: str, seqs: list, colon_id: int, out, settings: ScreeningSettings, identity: dict,
                frames_every: int, segment_mm: float, progress: bool = False) -> tuple[dict | None, dict]:
    """Check, see and write one whole-colon phantom's withdrawals as ``out/test/<name>.h5`` (see the module's
    description); its shard (None where every withdrawal is left out) and, per withdrawal, what was found (with
    ``skipped``, the reason, where it is left out)."""
    from colonbench.mapping.colonmap import map_centerline, single_segment
    from colonbench import seeding
    from colonbench._version import __version__
    from colonbench.datagen.camera import SurfaceScene
    from colonbench.meshes import sample_surface, triangle_areas
    from colonbench.polyline import Centerline
    from colonbench.progress import bar as progress_bar
    from colonbench.shards.colonshard import write_colon_shard
    from colonbench.video import c3vd
    from colonbench.video.c3vd_screening import check_trajectory, lumen_test, trajectory_visibility

    t0 = time.perf_counter()
    v, f, capped, centerline = _mesh_and_centerline(name, seqs)
    scene = SurfaceScene(v, f)
    inside = lumen_test(v, f, capped, scene)
    extent = float(np.linalg.norm(np.ptp(v, axis=0)))
    stored = v.astype(np.float32)
    area = triangle_areas(stored.astype(float), f)      # as the evaluation reads the truth back
    shard = f"test/{name}.h5"
    samples, reports, starts = [], {}, []
    for seq in seqs:
        t = time.perf_counter()
        raw = c3vd.read_poses(seq.poses)
        conv = check_trajectory(seq.name, raw, inside, extent, settings.min_inside, settings.min_span)
        poses = c3vd.camera_to_world(raw, conv["transposed"], conv["scale"])
        bar = progress_bar(total=len(range(0, len(poses), frames_every)), unit="frame", desc=f"see {seq.name}",
                           enabled=progress)
        try:
            observed, frames = trajectory_visibility(scene, poses, frames_every, settings.fov_deg, settings.reach_mm,
                                                     settings.near_mm, progress=bar.update if progress else None)
        finally:
            bar.close()
        if not observed.any():
            raise InputError(f"sequence {seq.name}: its camera sees no face of its phantom ({seq.mesh}) within "
                             f"{settings.reach_mm:g} mm along its trajectory")
        rng = seeding.rng(settings.seed, "c3vd-colon", seq.name)
        points = sample_surface(rng, v, f[observed], settings.point_density, areas=area[observed])
        coverage = float(area[observed].sum() / area.sum())
        positions = poses[:, :3, 3]
        reports[seq.name] = {"folder": seq.folder.name, "mesh": Path(seq.mesh).name, "colon": name, "shard": shard,
                             "index": len(samples), "faces": int(len(f)), "poses": int(len(raw)),
                             "frames_seen_from": int(len(frames)), "convention": conv, "observed_share": coverage,
                             "points": int(len(points)), "samples": 1}
        # the map's own line of this partial and its rule: a colon it takes for a single segment, every method fails
        pieces, _ = map_centerline(points.astype(float), positions)
        mapped = float(sum(p.length for p in pieces))
        reports[seq.name]["map_centerline_mm"] = mapped
        why = single_segment(mapped, segment_mm)
        if why:
            reports[seq.name].update(index=None, shard=None, samples=0, seconds=round(time.perf_counter() - t, 2),
                                     skipped=f"a screening withdrawal the whole-colon map cannot map ({why}; the map's "
                                             f"line of what its camera saw): left out")
            continue
        starts.append(positions[0])
        samples.append({"hole_model": "camera", "noise_mm": 0.0, "coverage": coverage, "observed_faces": observed,
                        "points": points, "positions": positions})
        reports[seq.name]["seconds"] = round(time.perf_counter() - t, 2)
    if not samples:
        return None, reports
    ends = centerline.point_at([0.0, centerline.length])
    mean_start = np.mean(starts, axis=0)
    if np.linalg.norm(ends[1] - mean_start) < np.linalg.norm(ends[0] - mean_start):
        centerline = Centerline.from_points(centerline.points[::-1])
    attrs = {"generator_version": __version__, **identity, "seed": settings.seed, "split": "test",
             "colon_id": int(colon_id), "colon_source": name, "colon_length_mm": float(centerline.length)}
    write_colon_shard(Path(out) / shard, attrs, stored, f.astype(np.int32), centerline, samples)
    for r in reports.values():
        r["centerline_mm"] = float(centerline.length)
    info = {"name": shard, "samples": len(samples), "segments": 0, "colon_id": int(colon_id),
            "coverage": [s["coverage"] for s in samples], "seconds": round(time.perf_counter() - t0, 2)}
    return info, reports


def write_colon_lock(out_dir, identity: dict, shards: list[dict]) -> dict:
    """The dataset lock of the suite's folder, as :func:`colonbench.shards.dataset.write_lock` describes a
    generated whole-colon dataset."""
    from colonbench.shards import schema, stats
    from colonbench.shards.c3vd_shards import write_built_lock
    from colonbench.shards.schema import sha256_file

    out = Path(out_dir)
    entries = {}
    for s in shards:
        path = out / s["name"]
        entries[s["name"]] = {"sha256": sha256_file(path), "bytes": path.stat().st_size, "samples": s["samples"],
                              "segments": 0, "split": "test", "colon_id": s["colon_id"], "length_mm": 0.0}
    split = {"test": {"shards": len(entries), "samples": sum(e["samples"] for e in entries.values()), "segments": 0,
                      "colons": len(entries), "bytes": sum(e["bytes"] for e in entries.values()),
                      "statistics": {"coverage": stats.quantiles(np.concatenate([s["coverage"] for s in shards]))}}}
    return write_built_lock(out, identity, split, entries, schema.COLON_FORMAT_VERSION)


def colon_job(screening, skipped: list, frames_every: int, progress: bool = False):
    """The whole-colon suite of a download's screening withdrawals: its id and its maker
    (:func:`colonbench.benchmark.local_suites.publish`). The maker adds the withdrawals it leaves out to
    ``skipped`` and returns None where it leaves out every one (no suite)."""
    from colonbench.benchmark.c3vd_suite import CITE, LICENCE, suite_identity

    t0 = time.perf_counter()
    settings = ScreeningSettings()
    base = protocol()
    options = {"frames_every": int(frames_every), "settings": settings.to_dict(), "noise_mm": list(base.noise_mm),
               "noise_seed": base.noise_seed, "contexts_mm": list(base.contexts_mm), "segment_mm": base.segment_mm}
    sid, identity, digests, digest_seconds = suite_identity(IMPORTER, IMPORTER_VERSION, options, screening)
    key = identity["manifest_sha256"]

    def make(tmp: Path) -> dict | None:
        shards, reports = [], {}
        for name, seqs in groups(screening):
            info, found = build_colon(name, seqs, len(shards), tmp, settings, identity, frames_every, base.segment_mm,
                                      progress)
            shards += [info] if info is not None else []
            reports.update(found)
            # a withdrawal left out is one of the download's skipped folders (every suite of the build lists them)
            skipped.extend({"folder": r["folder"], "reason": r["skipped"]} for r in found.values() if r.get("skipped"))
        if not shards:
            return None
        entry = _finish(tmp, sid, key, identity, screening, skipped, shards, reports, options, digests, base, t0)
        entry.update(digest_seconds=digest_seconds, licence=LICENCE, cite=list(CITE))
        return entry

    return sid, make


def _finish(tmp: Path, sid, key, identity, screening, skipped, shards, reports, options, digests, base, t0) -> dict:
    """Write the lock, signature and descriptive manifest of the suite's folder; its registry entry."""
    import yaml

    from colonbench.benchmark import local_suites, verification
    from colonbench.benchmark.evaluate import select
    from colonbench.benchmark.fingerprint import colons_fingerprint

    lock = write_colon_lock(tmp, identity, shards)
    (tmp / "manifest.yaml").write_text(yaml.safe_dump(
        {"name": sid, "task": "colon", "description": "built by colonbench suites build c3vd from the screening "
         "withdrawals of a C3VD download (not a generator manifest: it cannot be generated again without the "
         "download)", "importer": f"{IMPORTER} {IMPORTER_VERSION}", "options": options,
         "source_digest": digests["digest"]}, sort_keys=False))
    _, picks = select(tmp, "test", None)
    sha256, records = colons_fingerprint(tmp, picks, base.noise_mm, base.noise_seed)
    for r in records:   # every whole partial is drawn on the true surface
        r["cloud"] = "surface"
    stub = local_suites.LocalSuite(IMPORTER, IMPORTER_VERSION, "", "colon", "", len(records), sha256, 0.0,
                                   noise_mm=base.noise_mm, noise_seed=base.noise_seed, local_id=sid)
    published = verification.make(stub, lock, sha256, records)
    verification.write(published, tmp / local_suites.SIGNATURE_FILE)
    names = [s.name for s in screening if not reports[s.name].get("skipped")]
    tests = (f"real screening trajectories of C3VDv2: {len(names)} withdrawal(s) over {len(shards)} whole-colon "
             f"phantom(s) ({', '.join(sorted(names)[:4])}{', ...' if len(names) > 4 else ''}), what each saw by "
             f"colonbench's camera along it ({options['settings']['fov_deg']:g} degree view, "
             f"{options['settings']['near_mm']:g}-{options['settings']['reach_mm']:g} mm), mapped into "
             f"{base.segment_mm:g} mm segments as {base.id} is")
    sequences = {s.name: {**digests["sequences"][s.name], **reports[s.name]} for s in screening}
    return {"format": local_suites.FORMAT, "format_version": local_suites.FORMAT_VERSION, "id": sid,
            "name": IMPORTER, "version": IMPORTER_VERSION, "task": "colon", "tests": tests,
            "samples": len(records), "sha256": sha256, "signature": verification.digest(published),
            "noise_mm": list(base.noise_mm), "noise_seed": base.noise_seed, "contexts_mm": list(base.contexts_mm),
            "segment_mm": base.segment_mm, "protocol": base.id, "build_seconds": round(time.perf_counter() - t0, 1),
            "importer": {"name": IMPORTER, "version": IMPORTER_VERSION}, "options": options,
            "source": {"digest": digests["digest"], "files": digests["files"], "sequences": sequences,
                       "skipped": skipped}}
