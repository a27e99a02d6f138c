"""Whole-colon shards: one colon's true surface and its partial reconstructions, written, read and made.

The data of the whole-colon benchmark (``colonbench evaluate --task colon``,
docs/mapping.md). A manifest with ``task: colon`` makes one shard per colon
(procedural or imported), holding the colon's true surface and centerline once
and ``permutations`` whole partial reconstructions of it
(:func:`colonbench.datagen.wholecolon.whole_partial`), each with its exact
per-face observed mask and its withdrawal trajectory. The fields are defined in
:data:`colonbench.shards.schema.COLON_FIELDS`.

As for segment shards, every random number comes from a stream addressed by
``(colon, permutation)``, the file is written in a fixed order without
timestamps under a temporary name and renamed into place once complete.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import h5py
import numpy as np

from colonbench import seeding
from colonbench.errors import InputError
from colonbench.shards import schema
from colonbench.shards.reader import ragged_row, read_attrs
from colonbench.shards.writer import TMP_SUFFIX, _ragged, publish


def face_arclength(vertices: np.ndarray, faces: np.ndarray, centerline) -> np.ndarray:
    """(f,) float: arc length of the centerline point nearest to each face's centroid, mm.

    Parameters
    ----------
    vertices : (v, 3) float
    faces : (f, 3) int
    centerline : colonbench.polyline.Centerline
    """
    from scipy.spatial import cKDTree

    _, near = cKDTree(centerline.points).query(np.asarray(vertices)[faces].mean(axis=1))
    return centerline.arclength[near]


def write_colon_shard(path, attrs: dict, vertices, faces, centerline, samples: list[dict]) -> Path:
    """Write one whole-colon shard atomically.

    Parameters
    ----------
    path : path
        Final file name.
    attrs : dict
        Every key of :data:`~colonbench.shards.schema.COLON_ATTRIBUTES` (``format``,
        ``format_version`` and ``n_samples`` are filled in), plus optional ones.
    vertices : (v, 3) float
        The true surface, mm.
    faces : (f, 3) int
    centerline : colonbench.polyline.Centerline
        The GT centerline, caecum to anus.
    samples : list of dict
        One per sample: ``hole_model`` (name), ``noise_mm``, ``coverage``,
        ``observed_faces`` ((f,) bool), ``points`` ((n, 3) mm), ``positions`` ((k, 3) mm).
    """
    from colonbench.polyline import Centerline

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + f"{TMP_SUFFIX}{os.getpid()}")
    attrs = {**attrs, "format": schema.COLON_FORMAT, "format_version": schema.COLON_FORMAT_VERSION,
             "n_samples": len(samples)}
    missing = sorted(set(schema.COLON_ATTRIBUTES) - set(attrs))
    if missing:
        raise ValueError(f"whole-colon shard attributes missing: {missing}")
    stored = Centerline.from_points(np.asarray(centerline.points, np.float32))  # as it will be read back
    vertices = np.asarray(vertices, np.float32)
    columns = {
        "colon/vertices": vertices, "colon/faces": np.asarray(faces),
        "colon/centerline": stored.points, "colon/face_arclength": face_arclength(vertices, faces, stored),
        "samples/hole_model": [schema.HOLE_MODEL_CODES[s["hole_model"]] for s in samples],
        "samples/noise_mm": [s["noise_mm"] for s in samples], "samples/coverage": [s["coverage"] for s in samples],
        "samples/observed_faces": np.array([s["observed_faces"] for s in samples]).reshape(len(samples), len(faces)),
        "samples/points": [s["points"] for s in samples], "samples/positions": [s["positions"] for s in samples],
    }
    try:
        with h5py.File(tmp, "w") as h5:
            for f in schema.COLON_FIELDS:
                data = columns[f.path]
                if f.ragged:
                    flat, offsets = _ragged(data, f.dtype, (3,))
                    h5.create_dataset(f.path + "_offsets", data=offsets, track_times=False)
                    data = flat
                dtype = schema.hole_model_dtype() if f.name == "hole_model" else np.dtype(f.dtype)
                data = np.asarray(data).astype(dtype)
                opts = dict(schema.COMPRESSION) if data.size else {}
                h5.create_dataset(f.path, data=data, track_times=False, **opts)
            for key, val in attrs.items():
                h5.attrs[key] = val
        publish(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
    return path


class ColonShard:
    """A whole-colon shard, read.

    Parameters
    ----------
    path : path
        A ``.h5`` file written by :func:`write_colon_shard`.

    Raises
    ------
    InputError
        Not readable, not a whole-colon shard, or of another format version.
    """

    def __init__(self, path):
        self.path = Path(path)
        self.attrs = read_attrs(self.path)
        if self.attrs.get("format") != schema.COLON_FORMAT:
            what = "a segment shard" if self.attrs.get("format") == schema.FORMAT else "not a colonbench shard"
            raise InputError(f"{self.path}: {what}, not a whole-colon shard (made from a manifest with task: colon)")
        if int(self.attrs.get("format_version", -1)) != schema.COLON_FORMAT_VERSION:
            raise InputError(f"{self.path}: whole-colon shard format version {self.attrs.get('format_version')}, "
                             f"this colonbench reads version {schema.COLON_FORMAT_VERSION}")

    def __len__(self) -> int:
        return int(self.attrs["n_samples"])

    @property
    def name(self) -> str:
        """The colon's name: its mesh name, or ``colon-NNNNN``."""
        return self.attrs["colon_source"] or f"colon-{int(self.attrs['colon_id']):05d}"

    def colon(self) -> dict:
        """``vertices`` (v, 3) float64 mm, ``faces`` (f, 3) int64, ``centerline`` (a Centerline), ``face_arclength``."""
        from colonbench.polyline import Centerline

        with h5py.File(self.path, "r") as h5:
            return {"vertices": h5["colon/vertices"][()].astype(float), "faces": h5["colon/faces"][()].astype(np.int64),
                    "centerline": Centerline.from_points(h5["colon/centerline"][()]),
                    "face_arclength": h5["colon/face_arclength"][()].astype(float)}

    def sample(self, i: int) -> dict:
        """Sample ``i``: ``points`` (n, 3), ``positions`` (k, 3), ``observed_faces`` (f,) bool, ``hole_model``,
        ``noise_mm``, ``coverage``, ``index``."""
        if not 0 <= i < len(self):
            raise IndexError(f"{self.path}: sample {i} out of range ({len(self)} samples)")
        with h5py.File(self.path, "r") as h5:
            smp = h5["samples"]
            return {"index": i, "points": ragged_row(smp, "points", i).astype(float),
                    "positions": ragged_row(smp, "positions", i).astype(float),
                    "observed_faces": smp["observed_faces"][i].astype(bool),
                    "hole_model": schema.HOLE_MODEL_NAMES[int(smp["hole_model"][i])],
                    "noise_mm": float(smp["noise_mm"][i]),
                    "coverage": float(smp["coverage"][i])}


def build_colon_shard(resolved: dict, unit, out_dir) -> dict:
    """Make and write the whole-colon shard of one colon of a ``task: colon`` manifest.

    Parameters
    ----------
    resolved : dict
        A resolved manifest with ``task: colon``.
    unit : colonbench.shards.manifest.Unit
        A whole-colon unit (``unit.whole``).
    out_dir : path
        Dataset folder; the shard goes to ``out_dir / unit.name``.

    Returns
    -------
    dict
        ``name``, ``samples``, ``segments`` (0), ``seconds``.
    """
    import time

    from colonbench._version import __version__
    from colonbench.meshes import triangle_areas
    from colonbench.datagen.generate import GeneratorConfig, procedural_colon
    from colonbench.datagen.wholecolon import whole_partial
    from colonbench.shards.build import check_mesh_files, mesh_colon
    from colonbench.shards.manifest import config_hash, draw_mix, manifest_hash, stratified_draw

    t0 = time.perf_counter()
    seed = resolved["seed"]
    split = resolved["splits"][unit.split]
    config = GeneratorConfig.from_dict(resolved["config"])
    if unit.mesh is not None:
        check_mesh_files(unit)
        colon = mesh_colon(unit)
    else:
        colon = procedural_colon(config, seed, unit.colon_id)
    v = np.asarray(colon.mesh.vertices, np.float32)
    f = np.asarray(colon.mesh.faces, np.int32)
    area = triangle_areas(v.astype(float), f)
    samples = []
    perms = split["permutations"]
    for p in range(perms):
        holes = stratified_draw(split["hole_models"], perms, p, seed, "whole_hole_model", unit.colon_id)
        sigma = draw_mix(split["noise_mm"], seed, "whole_noise", unit.colon_id, p)
        sub_seed = int(seeding.seed_sequence(seed, "whole", unit.colon_id, p).generate_state(1)[0])
        part = whole_partial(colon, seed=sub_seed, holes=holes, config=config.whole)
        pts = part.points
        if sigma > 0:
            pts = pts + seeding.rng(seed, "whole_noise_values", unit.colon_id, p).normal(0.0, sigma, pts.shape)
        samples.append({"hole_model": holes, "noise_mm": sigma,
                        "coverage": float(area[part.observed].sum() / area.sum()),
                        "observed_faces": part.observed, "points": pts, "positions": part.positions})
    attrs = {"generator_version": __version__, "manifest_name": resolved["name"],
             "manifest_sha256": manifest_hash(resolved), "config_sha256": config_hash(resolved), "seed": seed,
             "split": unit.split, "colon_id": unit.colon_id, "colon_source": unit.mesh or "",
             "colon_length_mm": float(colon.centerline.length)}
    if unit.mesh is not None:
        attrs["collapsed_mm"] = json.dumps(colon.info.get("collapsed_mm", []))
    write_colon_shard(Path(out_dir) / unit.name, attrs, v, f, colon.centerline, samples)
    return {"name": unit.name, "samples": len(samples), "segments": 0,
            "seconds": {"colon+partials": time.perf_counter() - t0}}
