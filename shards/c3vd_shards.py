"""Shards of a C3VD sequence: its phantom cut into segments along its centerline, truth from C3VD's per-face
coverage, and its partial clouds, in the HDF5 format of every suite (:mod:`colonbench.shards.schema`).

For one registered sequence (read by :mod:`colonbench.video.c3vd`):

1. the phantom's centerline is the project's own line of the mesh
   (:func:`colonbench.datagen.mesh_centerline.open_tube_centerline`: the open ends capped, the lumen voxelized,
   the minimal path between its extremities);
2. the phantom is cut into consecutive windows of each of the suites' lengths (50, 60, 70 mm, ``end_margin_mm``
   left at each end; :func:`windows`). A phantom too short for 50 mm gives one window of what it allows, rounded
   down to 10 mm, if that is at least ``min_length_mm``;
3. each segment's truth is C3VD's: a face of the segment is observed when its parent face of the phantom mesh is
   (:func:`colonbench.datagen.segments.segment_surface` keeps the parent of every clipped face); coverage is the
   observed area over the segment's area, hole points are drawn on the unobserved faces (4 per mm^2);
4. two samples per segment, with the same truth: permutation 0, hole model ``camera``, the partial drawn on the
   observed faces (2 points per mm^2, exact: a perfect reconstruction of what the camera saw); permutation 1, hole
   model ``video``, where the sequence has depth frames: the fused surface of its frames
   (:mod:`colonbench.video.c3vd_fusion`) cut to the segment (between its planes, nearest to its stretch of the
   centerline) and sampled at the same density.

A segment (or one sample of it) is left out, with the reason in the shard's ``skipped_segments``, when its
partial has fewer than ``min_points`` points (nothing was seen there, or nothing fused).

5. the video check: a ``video`` sample's truth is C3VD's map, made from every pixel of every frame; its partial is
   what the fused frames hold. The two describe the same observation only where the partial reaches what the map
   calls observed. Per video sample, :func:`reach` measures the segment's observed area within
   ``reach_tolerance_mm`` (1.5 mm) of its fused surface; pooled over the sequence's video samples, the share of
   their observed area reached (:func:`video_check`) must be at least ``min_reach`` (0.95), or every video
   sample of the sequence is left out, the figure in the reason. The figure, per sample and pooled, is
   returned to be recorded.

Random draws descend from ``seed`` through the stream ``("c3vd", sequence, length in µm, segment, permutation)``
(the check's points: permutation ``"reach"``).
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from colonbench import seeding
from colonbench._version import __version__
from colonbench.datagen.camera import SurfaceScene
from colonbench.datagen.sample import hole_areas
from colonbench.datagen.segments import STRETCH_MARGIN_MM, clip_faces, segment_surface, windows
from colonbench.errors import ColonbenchError
from colonbench.grid import fit_grid
from colonbench.heatmaps import HEATMAP_SCALE, empty_grids, pack_occupancy, sample_occupancy
from colonbench.meshes import sample_surface
from colonbench.shards import schema
from colonbench.shards.writer import ShardWriter


@dataclass(frozen=True)
class ImportSettings:
    """How a C3VD sequence is cut and sampled (the suites' protocol: segment lengths, densities, grid)."""

    lengths_mm: tuple = (50.0, 60.0, 70.0)
    end_margin_mm: float = 10.0
    min_length_mm: float = 30.0
    point_density: float = 2.0
    hole_point_density: float = 4.0
    min_points: int = 100
    grid_size: int = 64
    grid_margin: int = 4
    grid_min_extent_mm: float = 70.0
    grid_axes: str = "tube"
    reach_tolerance_mm: float = 1.5
    min_reach: float = 0.95
    seed: int = 0

    def to_dict(self) -> dict:
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(self).items()}


def segment_windows(length_mm: float, settings: ImportSettings) -> list[tuple[float, list]]:
    """``[(segment length, [(s0, s1), ...]), ...]``: the windows of each length the centerline holds, or one
    window of a shorter length where it holds none (see the module's description); [] when too short."""
    out = [(float(L), w) for L in settings.lengths_mm if (w := windows(length_mm, L, settings.end_margin_mm))]
    if not out:
        short = 10.0 * np.floor((length_mm - 2 * settings.end_margin_mm) / 10.0 + 1e-9)
        if short >= settings.min_length_mm:
            out = [(float(short), windows(length_mm, short, settings.end_margin_mm))]
    return out


def fused_in_window(fused: dict, centerline, s0: float, s1: float, margin_mm: float = STRETCH_MARGIN_MM):
    """The fused surface between a segment's planes, on its own stretch of the centerline: vertices, faces."""
    v, f = fused["vertices"], fused["faces"]
    if len(f) == 0:
        return v, f
    _, s_near = centerline.closest(v[f].mean(axis=1))
    near = (s_near >= s0 - margin_mm) & (s_near <= s1 + margin_mm)
    c0, c1 = centerline.point_at([s0, s1])
    t0, t1 = centerline.tangent_at([s0, s1])
    v, f, _ = clip_faces(v, f[near], np.zeros(int(near.sum()), np.int64), c0, t0)
    v, f, _ = clip_faces(v, f, np.zeros(len(f), np.int64), c1, -t1)
    return v, f


def _sample_row(settings, partial, surface, verts64, faces, centerline64, observed, coverage, holes, areas, p,
                hole_model):
    """The grids and fields of one sample, or the reason it cannot be made."""
    if len(partial) < settings.min_points:
        return None, f"{hole_model}: {len(partial)} partial points, fewer than {settings.min_points}"
    partial = partial.astype(np.float32)
    partial64 = partial.astype(float)
    grid = fit_grid(partial64, size=settings.grid_size, margin=settings.grid_margin,
                    min_extent_mm=settings.grid_min_extent_mm, axes=settings.grid_axes)
    occ = sample_occupancy(grid, partial64, verts64, faces, centerline64)
    empty = empty_grids(occ.grids)
    if empty:
        return None, f"{hole_model}: nothing of its {' and '.join(empty)} inside its grid"
    grids = {name: pack_occupancy(g) for name, g in occ.grids.items()}
    return (grids, dict(grid_affine=grid.affine, permutation=p, hole_model=schema.HOLE_MODEL_CODES[hole_model],
                        noise_mm=0.0, coverage=coverage, outside_grid=occ.outside["complete"],
                        observed_faces=observed, partial_points=partial, hole_points=holes,
                        hole_areas_mm2=areas)), ""


def reach(mesh, observed, fused_vertices, fused_faces, rng, tolerance_mm: float, density: float):
    """What a fused partial reaches of a segment's observed surface: the observed area (mm^2) and the part of it
    within ``tolerance_mm`` of the fused surface (estimated from points drawn on the observed faces, ``density``
    per mm^2)."""
    areas = mesh.area_faces[observed]
    seen = float(areas.sum())
    if seen == 0 or len(fused_faces) == 0:
        return seen, 0.0
    points = sample_surface(rng, mesh.vertices, mesh.faces[observed], density, areas=areas)
    if len(points) == 0:
        return seen, 0.0
    near = SurfaceScene(fused_vertices, fused_faces).distance(points) <= tolerance_mm
    return seen, seen * float(near.mean())


def video_check(reached: list[dict], settings: ImportSettings) -> dict | None:
    """The sequence's video check: the share of its video samples' observed area their fused partials reach
    (:func:`reach`), pooled over the samples, against ``settings.min_reach``; None without video samples."""
    if not reached:
        return None
    share = sum(r["reached_mm2"] for r in reached) / max(sum(r["observed_mm2"] for r in reached), 1e-12)
    each = [r["reached_mm2"] / r["observed_mm2"] if r["observed_mm2"] > 0 else 1.0 for r in reached]
    return {"reach": float(share), "threshold": settings.min_reach, "tolerance_mm": settings.reach_tolerance_mm,
            "samples": len(reached), "min_sample": float(min(each)), "passed": bool(share >= settings.min_reach)}


def refusal(check: dict) -> str:
    """Why a sequence's video samples are left out, with its figure."""
    return (f"video: the fused partials reach {check['reach']:.1%} of their segments' observed area within "
            f"{check['tolerance_mm']:g} mm, under the {check['threshold']:.0%} needed for the truth to describe "
            "what they hold: every video sample of the sequence left out (fuse more frames: --frames-every 1)")


def write_sequence_shards(out_dir, name: str, colon_id: int, vertices, faces, observed, centerline,
                          fused: dict | None, settings: ImportSettings, identity: dict) -> tuple[list, list, dict]:
    """Cut one sequence's phantom and write one shard per segment length, ``out_dir/test/<name>-<L>mm.h5``.

    Parameters
    ----------
    out_dir : path
    name : str
        The sequence.
    colon_id : int
        Its number in the suite.
    vertices : (n, 3) float, mm
    faces : (m, 3) int
    observed : (m,) bool
        C3VD's per-face coverage.
    centerline : Centerline
    fused : dict or None
        :func:`colonbench.video.c3vd_fusion.fuse_sequence`'s surface, or None (no depth frames).
    settings : ImportSettings
    identity : dict
        ``manifest_name``, ``manifest_sha256``, ``config_sha256``: the suite's, written into every shard.

    Returns
    -------
    shards : list of dict
        ``name`` (relative to ``out_dir``), ``samples``, ``segments``, ``length_mm``, ``colon_id``.
    skipped : list of dict
        Segments and samples left out, with the length, window and reason.
    check : dict or None
        :func:`video_check` of the video samples made (None without); where it fails, they are all left out.
    """
    observed = np.asarray(observed, bool)
    scene = SurfaceScene(vertices, faces)
    cut, reached = [], []
    for length, wins in segment_windows(centerline.length, settings):
        lmm = int(round(length * 1000))
        rows, left_out = [], []
        for k, (s0, s1) in enumerate(wins):
            where = {"window_mm": [float(s0), float(s1)], "segment": k}
            try:
                surface = segment_surface(scene, centerline, s0, s1)
            except ColonbenchError as exc:   # no wall there (a gap in the phantom's mesh)
                left_out.append({**where, "reason": str(exc)})
                continue
            mesh = surface.mesh
            obs = observed[surface.parent_face]
            areas = mesh.area_faces
            coverage = float(areas[obs].sum() / areas.sum())
            verts, tris = mesh.vertices.astype(np.float32), mesh.faces.astype(np.int32)
            cl = surface.centerline.astype(np.float32)
            rng = seeding.rng(settings.seed, "c3vd", name, lmm, k, 0)
            partial = sample_surface(rng, mesh.vertices, mesh.faces[obs], settings.point_density, areas=areas[obs])
            holes = sample_surface(rng, mesh.vertices, mesh.faces[~obs], settings.hole_point_density,
                                   areas=areas[~obs]).astype(np.float32)
            pieces = hole_areas(mesh, obs)
            made = []
            candidates = [("camera", partial)]
            if fused is not None:
                fv, ff = fused_in_window(fused, centerline, s0, s1)
                rng_b = seeding.rng(settings.seed, "c3vd", name, lmm, k, 1)
                candidates.append(("video", sample_surface(rng_b, fv, ff, settings.point_density)
                                   if len(ff) else np.zeros((0, 3))))
            for p, (model, points) in enumerate(candidates):
                row, why = _sample_row(settings, points, surface, verts.astype(float), tris, cl.astype(float),
                                       obs, coverage, holes, pieces, p, model)
                if row is None:
                    left_out.append({**where, "reason": why})
                    continue
                made.append((model, row))
                if model == "video":
                    seen, near = reach(mesh, obs, fv, ff, seeding.rng(settings.seed, "c3vd", name, lmm, k, "reach"),
                                       settings.reach_tolerance_mm, settings.hole_point_density)
                    reached.append({"length_mm": length, **where, "observed_mm2": seen, "reached_mm2": near})
            if made:
                rows.append((k, surface, verts, tris, cl, made, where))
        cut.append((length, rows, left_out))
    check = video_check(reached, settings)
    if check is not None:
        check["segments"] = [{"length_mm": r["length_mm"], "segment": r["segment"],
                              "reach": round(r["reached_mm2"] / r["observed_mm2"], 4) if r["observed_mm2"] else None}
                             for r in reached]
    shards, skipped = [], []
    for length, rows, left_out in cut:
        if check is not None and not check["passed"]:
            why = refusal(check)
            left_out += [{**r[6], "reason": why} for r in rows if any(m == "video" for m, _ in r[5])]
            rows = [(*r[:5], [(m, x) for m, x in r[5] if m != "video"], r[6]) for r in rows]
            rows = [r for r in rows if r[5]]
        skipped += [{"length_mm": length, **s} for s in left_out]
        shard = _write_shard(out_dir, name, colon_id, length, rows, left_out, settings, identity)
        if shard is not None:
            shards.append(shard)
    return shards, skipped, check


def _write_shard(out_dir, name, colon_id, length, rows, left_out, settings, identity) -> dict | None:
    """One segment length's shard of a sequence, or None where it holds no sample."""
    n = sum(len(r[5]) for r in rows)
    if n == 0:
        return None
    shard = f"test/{name}-{length:g}mm.h5"
    attrs = {"format": schema.FORMAT, "format_version": schema.FORMAT_VERSION, "generator_version": __version__,
             **identity, "seed": settings.seed, "split": "test", "colon_id": int(colon_id), "length_mm": length,
             "grid_size": settings.grid_size, "grid_margin": settings.grid_margin,
             "grid_min_extent_mm": settings.grid_min_extent_mm, "heatmap_scale": HEATMAP_SCALE, "n_samples": n,
             "n_segments": len(rows), "colon_source": name, "skipped_segments": json.dumps(left_out)}
    if settings.grid_axes != "pca":
        attrs["grid_axes"] = settings.grid_axes
    with ShardWriter(Path(out_dir) / shard, n, settings.grid_size) as writer:
        for k, surface, verts, tris, cl, made, _ in rows:
            row = writer.add_segment(segment_id=k, window_mm=surface.window, complete_area_mm2=surface.mesh.area,
                                     vertices=verts, faces=tris, centerline=cl)
            for _, (grids, fields) in made:
                writer.add_sample(grids, segment=row, **fields)
        writer.close(attrs)
    return {"name": shard, "samples": n, "segments": len(rows), "length_mm": length, "colon_id": int(colon_id)}


def write_lock(out_dir, identity: dict, shards: list[dict]) -> dict:
    """The dataset lock (:data:`schema.LOCK_NAME`) of an imported suite's folder: every shard's sha256, size and
    counts, and the test split's statistics, as :func:`colonbench.shards.dataset.write_lock` describes a
    generated dataset."""
    from colonbench.shards import stats
    from colonbench.shards.schema import sha256_file

    out = Path(out_dir)
    entries, values = {}, []
    for s in shards:
        path = out / s["name"]
        entries[s["name"]] = {"sha256": sha256_file(path), "bytes": path.stat().st_size, "samples": s["samples"],
                              "segments": s["segments"], "split": "test", "colon_id": s["colon_id"],
                              "length_mm": s["length_mm"]}
        values.append(stats.shard_values(path))
    split = {"test": {"shards": len(entries), "samples": sum(e["samples"] for e in entries.values()),
                      "segments": sum(e["segments"] for e in entries.values()),
                      "colons": len({e["colon_id"] for e in entries.values()}),
                      "bytes": sum(e["bytes"] for e in entries.values()), "statistics": stats.summarize(values)}}
    return write_built_lock(out, identity, split, entries, schema.FORMAT_VERSION)


def write_built_lock(out: Path, identity: dict, split: dict, entries: dict, shard_format: int) -> dict:
    """Write a built suite's dataset lock (:data:`schema.LOCK_NAME`, as ``colonbench generate`` writes one) atomically,
    and return it."""
    import os

    lock = {"format": "colonbench-dataset-lock", "format_version": 1, **identity, "generator_version": __version__,
            "shard_format_version": shard_format, "splits": split, "missing": [], "shards": entries}
    tmp = Path(out) / (schema.LOCK_NAME + ".tmp")
    tmp.write_text(json.dumps(lock, indent=1) + "\n")
    os.replace(tmp, Path(out) / schema.LOCK_NAME)
    return lock
