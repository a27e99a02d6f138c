"""Making one shard: a colon at one segment length, all its selected segments and hole permutations.

:func:`build_shard` is the unit of work that every executor (one process, a
process pool, a Dask cluster) runs. It depends only on the resolved manifest
and the unit, draws every random number from streams addressed by
``(colon, length, segment, permutation)``, and writes the file in a fixed
order without timestamps, so the bytes of a shard do not depend on which
worker made it, when, or next to what.

The file is written by :class:`~colonbench.shards.writer.ShardWriter`: under a
temporary name, renamed into place only once complete and flushed, so a
killed run never leaves a partial file under a shard's name.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from colonbench import seeding
from colonbench._version import __version__
from colonbench.datagen.generate import GeneratorConfig, PreparedColon, procedural_colon
from colonbench.datagen.sample import make_sample
from colonbench.errors import ColonbenchError
from colonbench.grid import fit_grid
from colonbench.heatmaps import HEATMAP_SCALE, empty_grids, pack_occupancy, sample_occupancy
from colonbench.shards import schema
from colonbench.shards.manifest import Unit, config_hash, draw_mix, manifest_hash, pick_segments
from colonbench.shards.schema import sha256_file
from colonbench.shards.writer import ShardWriter
import colonbench.video  # noqa: F401 - registers the video hole model with the generator

_COLON_CACHE: dict = {}


def _prepared_colon(config: GeneratorConfig, seed: int, unit: Unit, key: str) -> PreparedColon:
    """The colon of a unit, kept for the next unit of the same colon in this process (one at a time)."""
    ck = (key, seed, unit.colon_id, unit.source)
    if unit.mesh is not None:
        check_mesh_files(unit)  # every time: the files may have changed since the colon was cached
    if ck not in _COLON_CACHE:
        _COLON_CACHE.clear()
        _COLON_CACHE[ck] = PreparedColon(mesh_colon(unit) if unit.mesh is not None
                                         else procedural_colon(config, seed, unit.colon_id))
    return _COLON_CACHE[ck]


def check_mesh_files(unit: Unit) -> None:
    """Raise unless a mesh unit's files exist and are the ones the manifest names (by sha256)."""
    name, mesh, mesh_sha, centerline, centerline_sha = unit.source
    for path, digest in ((mesh, mesh_sha), (centerline, centerline_sha)):
        if not Path(path).is_file():
            raise ColonbenchError(f"mesh {name!r}: {path} does not exist (paths are relative to the manifest)")
        if sha256_file(path) != digest:
            raise ColonbenchError(f"mesh {name!r}: {path} is not the file the manifest names (sha256 differs)")


def mesh_colon(unit: Unit):
    """The imported colon of a mesh unit: its lumen as colonoscopy sees it."""
    from colonbench.datagen.realmesh import import_colon

    _, mesh, _, centerline, _ = unit.source
    return import_colon(mesh, centerline, lumen=True)


class _Stages:
    """Wall time per stage, seconds."""

    def __init__(self):
        self.t = {}

    def add(self, name, since):
        now = time.perf_counter()
        self.t[name] = self.t.get(name, 0.0) + now - since
        return now


def build_shard(resolved: dict, unit: Unit, out_dir, version: int = schema.FORMAT_VERSION) -> dict:
    """Generate and write one shard; returns what was done.

    Parameters
    ----------
    resolved : dict
        A resolved manifest (:func:`colonbench.shards.manifest.resolve`).
    unit : Unit
    out_dir : path
        Dataset folder; the shard goes to ``out_dir / unit.name``.
    version : int
        Shard format (:mod:`colonbench.shards.schema`); 1, which stores the
        heatmaps, only to compare with the current format.

    Returns
    -------
    dict
        ``name``, ``samples``, ``segments``, ``seconds`` (per stage).
    """
    if unit.whole:
        from colonbench.shards.colonshard import build_colon_shard

        return build_colon_shard(resolved, unit, out_dir)
    stages = _Stages()
    t = time.perf_counter()
    seed = resolved["seed"]
    split = resolved["splits"][unit.split]
    size, margin, min_extent = (resolved["grid"][k] for k in ("size", "margin", "min_extent_mm"))
    axes = resolved["grid"].get("axes", "pca")
    config = GeneratorConfig.from_dict(resolved["config"])
    prepared = _prepared_colon(config, seed, unit, config_hash(resolved))
    t = stages.add("colon", t)
    wins, skipped = prepared.usable_windows(unit.length_mm, config.segments.end_margin_mm)
    picks = pick_segments(len(wins), split["segments_per_length"])
    if not picks:
        raise ColonbenchError(f"{unit.name}: colon {unit.colon_id} is too short for one {unit.length_mm:g} mm segment")
    perms = split["permutations"]
    n = len(picks) * perms
    lmm = int(round(unit.length_mm * 1000))

    attrs = {"format": schema.FORMAT, "format_version": int(version), "generator_version": __version__,
             "manifest_name": resolved["name"], "manifest_sha256": manifest_hash(resolved),
             "config_sha256": config_hash(resolved), "seed": seed, "split": unit.split, "colon_id": unit.colon_id,
             "length_mm": unit.length_mm, "grid_size": size, "grid_margin": margin,
             "grid_min_extent_mm": min_extent, "heatmap_scale": HEATMAP_SCALE,
             "n_samples": n, "n_segments": len(picks)}
    if axes != "pca":
        attrs["grid_axes"] = axes
    if unit.mesh is not None:
        attrs["colon_source"] = unit.mesh
        attrs["skipped_segments"] = json.dumps(skipped)
    sample_info = []
    quantize = unit.split in schema.QUANTIZED_SPLITS
    with ShardWriter(Path(out_dir) / unit.name, n, size, version=version, quantize=quantize) as writer:
        for k in picks:
            surface = prepared.segment(*wins[k])
            # the grids are made from the geometry as stored (float32), so they can be remade from the file
            verts = surface.mesh.vertices.astype(np.float32)
            faces = surface.mesh.faces.astype(np.int32)
            centerline = surface.centerline.astype(np.float32)
            row = writer.add_segment(segment_id=k, window_mm=surface.window, complete_area_mm2=surface.mesh.area,
                                     vertices=verts, faces=faces, centerline=centerline)
            verts64, centerline64 = verts.astype(float), centerline.astype(float)  # once for all permutations
            t = stages.add("segment", t)
            for p in range(perms):
                hole_model = draw_mix(split["hole_models"], seed, "hole_model", unit.colon_id, lmm, k, p)
                sigma = draw_mix(split["noise_mm"], seed, "noise", unit.colon_id, lmm, k, p)
                rng = seeding.rng(seed, "sample", unit.colon_id, lmm, k, p)
                s = make_sample(rng, prepared.scene, prepared.colon.centerline, surface, hole_model,
                                config.camera, config.spheres, config.segments, noise_mm=sigma,
                                video=config.video)
                sample_info.append(s.info.get("video"))
                partial = s.partial_points.astype(np.float32)
                partial64 = partial.astype(float)
                t = stages.add("sample", t)
                grid = fit_grid(partial64, size=size, margin=margin, min_extent_mm=min_extent, axes=axes)
                occ = sample_occupancy(grid, partial64, verts64, faces, centerline64)
                empty = empty_grids(occ.grids)
                if empty:
                    raise ColonbenchError(f"{unit.name}: segment {k}, permutation {p}: nothing of its "
                                          f"{' and '.join(empty)} falls inside its grid (no heatmap can be made)")
                if version == 1:
                    hm = occ.heatmaps()
                    grids = {"input": hm.input, "target": hm.target}
                else:
                    grids = {name: pack_occupancy(grid) for name, grid in occ.grids.items()}
                t = stages.add("grids", t)
                writer.add_sample(grids, grid_affine=grid.affine, segment=row, permutation=p,
                                  hole_model=schema.HOLE_MODEL_CODES[hole_model], noise_mm=sigma,
                                  coverage=s.coverage, outside_grid=occ.outside["complete"],
                                  observed_faces=s.observed_faces, partial_points=partial,
                                  hole_points=s.hole_points, hole_areas_mm2=s.hole_areas)
                t = stages.add("write", t)
        if any(i is not None for i in sample_info):
            attrs["sample_info"] = json.dumps(sample_info)
        writer.close(attrs)  # compresses and writes the rows kept until now
        stages.add("write", t)
    return {"name": unit.name, "samples": n, "segments": len(picks), "seconds": stages.t}
