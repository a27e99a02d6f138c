"""The HDF5 shard format: every stored field, its shape, dtype, units and frame, defined once.

A shard is one HDF5 file holding the samples of one colon at one segment
length for one split. It has two groups:

``segments/``
    One row per segment (``M`` rows): the complete surface mesh, the GT
    centerline and the arc-length window, stored once however many hole
    permutations the segment has.
``samples/``
    One row per sample (``N`` rows) = one hole permutation of one segment: the
    three 64^3 occupancy grids the heatmaps are functions of (bit-packed),
    the grid transform, the partial points, GT hole points, coverage, ...;
    ``samples/segment`` gives its row in ``segments/``.

A field whose rows have different lengths (point sets, meshes) is *ragged*: it
is stored as one flat array, and ``<name>_offsets`` (rows + 1 int64 values,
starting at 0) gives where each row starts and ends: row ``i`` is
``flat[offsets[i]:offsets[i + 1]]``.

Geometry is in mm in the colon's frame (the frame of the partial points).
Occupancies are in voxel space; ``samples/grid_affine`` maps a voxel index
``(i, j, k, 1)`` of ``s0[n]``, ``s1[n]`` and ``c[n]`` to mm (see
:class:`colonbench.grid.Grid`). The heatmaps are not stored: readers make them
(:meth:`colonbench.shards.reader.Shard.heatmaps`). Format 1 stored them
(float16 ``input`` and ``target``) instead of the occupancies; readers read
both (:data:`FIELDS_V1`).

In the ``train`` and ``validation`` splits the partial and hole points are
stored as int32 micrometres (:data:`POINT_SCALE_MM`; the dataset attributes
``scale_mm`` and ``offset_mm`` give ``mm = int * scale_mm + offset_mm``); the
``test`` split, the benchmark's inputs, keeps them as float32 exactly as made.

The docs table (``docs/shards.md``) is written from :data:`FIELDS` by
:func:`describe`; :func:`check` is what ``colonbench verify`` runs.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass

import h5py
import numpy as np

#: The lock file of a generated dataset folder (what it holds: :mod:`colonbench.shards.dataset`).
LOCK_NAME = "dataset.lock.json"


def sha256_file(path, block: int = 1 << 22) -> str:
    """SHA-256 (hex) of a file's bytes (the checksum dataset locks and pack descriptions record)."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(block), b""):
            h.update(chunk)
    return h.hexdigest()


#: Value of the file attribute ``format``.
FORMAT = "colonbench-shard"
#: Bumped whenever a field is added, removed or changes meaning.
FORMAT_VERSION = 2
#: The versions this colonbench reads (1: heatmaps stored; 2: occupancies stored).
READ_VERSIONS = (1, 2)
#: The splits whose point sets are stored in micrometres (int32); others keep float32.
QUANTIZED_SPLITS = ("train", "validation")
#: One stored point unit in a quantized split, mm (1 µm: 1/1400 of a voxel, 1/500 of the 0.5 mm noise).
POINT_SCALE_MM = 1e-3
#: The occupancy grids a format-2 sample stores, in this order (packs store the same).
OCCUPANCIES = ("s0", "s1", "c")

#: Hole models, as stored in the enum ``samples/hole_model``.
HOLE_MODEL_CODES = {"camera": 0, "spheres": 1, "camera+spheres": 2, "camera+end": 3, "spheres+end": 4,
                    "camera+spheres+end": 5, "video": 6}
#: The hole model of each stored code.
HOLE_MODEL_NAMES = {v: k for k, v in HOLE_MODEL_CODES.items()}


@dataclass(frozen=True)
class Field:
    """One stored dataset.

    Attributes
    ----------
    group : {"samples", "segments"}
    name : str
    dtype : str
        numpy dtype string as stored.
    shape : tuple
        ``"rows"`` for the group's row count, ``"S"`` for the grid side,
        ``"S^3/8"`` for a bit-packed grid's bytes, ``"flat"`` for the total
        length of a ragged field, or an int.
    unit, frame, doc : str
    ragged : bool
        Stored flat with ``<name>_offsets``.
    quantized : bool
        A point set stored as int32 micrometres in the :data:`QUANTIZED_SPLITS`.
    """

    group: str
    name: str
    dtype: str
    shape: tuple
    unit: str
    frame: str
    doc: str
    ragged: bool = False
    quantized: bool = False

    @property
    def path(self) -> str:
        return f"{self.group}/{self.name}"


FIELDS = (
    # --- segments/: one row per segment ---
    Field("segments", "segment_id", "int32", ("rows",), "-", "-",
          "index of the segment's window along the colon at this length (0 = caecum end)"),
    Field("segments", "window_mm", "float64", ("rows", 2), "mm", "colon centerline arc length",
          "arc-length window [s0, s1] of the segment on the colon's centerline"),
    Field("segments", "complete_area_mm2", "float64", ("rows",), "mm^2", "-", "area of the complete segment surface"),
    Field("segments", "vertices", "float32", ("flat", 3), "mm", "colon", "complete surface mesh vertices", True),
    Field("segments", "faces", "int32", ("flat", 3), "-", "-",
          "complete surface triangles, indices into the segment's own vertices (0-based)", True),
    Field("segments", "centerline", "float32", ("flat", 3), "mm", "colon",
          "GT centerline inside the segment, ordered from s0 to s1, spacing <= 0.5 mm", True),
    # --- samples/: one row per sample (segment x hole permutation) ---
    Field("samples", "s0", "uint8", ("rows", "S^3/8"), "-", "grid (i, j, k)",
          "S0: voxels holding a partial point (the input heatmap's zeros); numpy.packbits of the (S, S, S) grid "
          "in C order"),
    Field("samples", "s1", "uint8", ("rows", "S^3/8"), "-", "grid (i, j, k)",
          "S1: voxels the complete surface passes through (the target's zeros); packed as s0"),
    Field("samples", "c", "uint8", ("rows", "S^3/8"), "-", "grid (i, j, k)",
          "C: voxels the GT centerline passes through; packed as s0"),
    Field("samples", "grid_affine", "float64", ("rows", 4, 4), "mm per voxel", "grid -> colon",
          "maps voxel index (i, j, k, 1) to (x, y, z, 1) mm; fitted to the partial points alone"),
    Field("samples", "segment", "int32", ("rows",), "-", "-", "row of the sample's segment in segments/"),
    Field("samples", "permutation", "int32", ("rows",), "-", "-", "hole permutation index within the segment"),
    Field("samples", "hole_model", "uint8", ("rows",), "-", "-",
          "enum: 0 camera, 1 spheres, 2 camera+spheres, 3 camera+end, 4 spheres+end, 5 camera+spheres+end, 6 video "
          "(names in the dataset's enum type)"),
    Field("samples", "noise_mm", "float32", ("rows",), "mm", "-",
          "sigma of the Gaussian noise added to the partial points (0 = noiseless)"),
    Field("samples", "coverage", "float64", ("rows",), "fraction", "-",
          "GT coverage: observed area / complete area of the segment, in [0, 1]"),
    Field("samples", "outside_grid", "float32", ("rows",), "fraction", "-",
          "share of the complete surface that fell outside the grid (missing from the target)"),
    Field("samples", "observed_faces", "uint8", ("flat",), "-", "-",
          "1 where the face of the segment's complete mesh was observed; one value per face", True),
    Field("samples", "partial_points", "float32", ("flat", 3), "mm", "colon",
          "partial point cloud (the method's input), noise included; int32 µm in train and validation splits",
          True, True),
    Field("samples", "hole_points", "float32", ("flat", 3), "mm", "colon",
          "GT hole points: dense samples (4/mm^2) of the unobserved part of the complete surface; int32 µm in "
          "train and validation splits", True, True),
    Field("samples", "hole_areas_mm2", "float32", ("flat",), "mm^2", "-",
          "area of each hole (connected unobserved region), largest first", True),
)

#: Format 1's heatmaps, stored where format 2 stores the occupancies (read, never written).
HEATMAP_FIELDS = (
    Field("samples", "input", "float16", ("rows", "S", "S", "S"), "-", "grid (i, j, k)",
          "input heatmap tanh(0.2 d(v, S0)), d in voxels"),
    Field("samples", "target", "float16", ("rows", "S", "S", "S"), "-", "grid (i, j, k)",
          "target heatmap tanh(0.2 d(v,S1)) / (tanh(0.2 d(v,S1)) + tanh(0.2 d(v,C)))"),
)
#: The fields of a format-1 shard.
FIELDS_V1 = (tuple(f for f in FIELDS if f.group == "segments") + HEATMAP_FIELDS
             + tuple(f for f in FIELDS if f.group == "samples" and f.name not in OCCUPANCIES))


def fields_of(version: int) -> tuple:
    """The fields of a shard of format ``version`` (1 or 2)."""
    return FIELDS_V1 if int(version) == 1 else FIELDS


#: File attributes every shard carries, with their meaning.
ATTRIBUTES = {
    "format": f"always {FORMAT!r}",
    "format_version": f"shard format version (this one: {FORMAT_VERSION})",
    "generator_version": "colonbench version that wrote the file",
    "manifest_name": "name of the manifest",
    "manifest_sha256": "hash of the resolved manifest (see colonbench.shards.manifest)",
    "config_sha256": "hash of the full generator config",
    "seed": "root seed of the dataset",
    "split": "train, validation or test",
    "colon_id": "procedural colon index (the colon's random stream)",
    "length_mm": "segment arc length, mm",
    "grid_size": "heatmap side S, voxels",
    "grid_margin": "voxels left between the partial points' bounding box and the grid border",
    "grid_min_extent_mm": "smallest box side the grid is fitted to, mm (colonbench.grid.fit_grid)",
    "heatmap_scale": "the 0.2 in tanh(0.2 d)",
    "n_samples": "rows of samples/",
    "n_segments": "rows of segments/",
}

#: Attributes a shard carries only where they apply; absent means the value in brackets.
OPTIONAL_ATTRIBUTES = {
    "grid_axes": "how the grid axes were found: 'tube' (colonbench.grid.tube_axes) or 'pca' [pca]",
    "colon_source": "the imported colon mesh a shard was cut from, by its manifest name; procedural colons have "
                    "none ['']",
    "skipped_segments": "JSON list of the segments left out, each with its window and the reason ('[]')",
    "sample_info": "JSON list with one entry per row of samples/: what a video sample drew (its degradation "
                   "settings, reach, frames rendered and fused), null for other hole models; present only when "
                   "the shard holds a video sample",
}

# --- whole-colon shards (the whole-colon benchmark, ``colonbench evaluate --task colon``) ---

#: Value of the file attribute ``format`` of a whole-colon shard.
COLON_FORMAT = "colonbench-colon-shard"
#: Bumped whenever a whole-colon field is added, removed or changes meaning.
COLON_FORMAT_VERSION = 1

#: A whole-colon shard holds one colon (``colon/``: its true surface, once) and its partial reconstructions
#: (``samples/``, ``N`` rows, one per hole permutation). ``F`` is the colon's face count; every face's observed
#: flag is stored per sample, so the truth of any region of the colon can be counted exactly.
COLON_FIELDS = (
    Field("colon", "vertices", "float32", ("V", 3), "mm", "colon", "the complete (true) surface's vertices"),
    Field("colon", "faces", "int32", ("F", 3), "-", "-", "the complete surface's triangles (0-based)"),
    Field("colon", "centerline", "float32", ("C", 3), "mm", "colon",
          "GT centerline from the caecum (arc length 0) to the anus, spacing <= 1 mm"),
    Field("colon", "face_arclength", "float32", ("F",), "mm", "colon centerline arc length",
          "arc length of the GT centerline point nearest to each face's centroid: the stretch of colon the face "
          "belongs to (how a map's segments are scored)"),
    Field("samples", "hole_model", "uint8", ("rows",), "-", "-",
          "whole-colon hole model: 0 camera (a withdrawing colonoscope's views), 1 spheres (enum as samples/ of "
          "segment shards)"),
    Field("samples", "noise_mm", "float32", ("rows",), "mm", "-", "sigma of the Gaussian noise on the points"),
    Field("samples", "coverage", "float64", ("rows",), "fraction", "-",
          "GT whole-colon coverage: observed area / complete area"),
    Field("samples", "observed_faces", "uint8", ("rows", "F"), "-", "-", "1 where the face was observed"),
    Field("samples", "points", "float32", ("flat", 3), "mm", "colon",
          "the partial reconstruction (a method's input), noise included", True),
    Field("samples", "positions", "float32", ("flat", 3), "mm", "colon",
          "camera positions of the withdrawal in time order, caecum to rectum (colonbench map --trajectory)", True),
)

#: File attributes every whole-colon shard carries.
COLON_ATTRIBUTES = {
    "format": f"always {COLON_FORMAT!r}",
    "format_version": f"whole-colon shard format version (this one: {COLON_FORMAT_VERSION})",
    "generator_version": "colonbench version that wrote the file",
    "manifest_name": "name of the manifest",
    "manifest_sha256": "hash of the resolved manifest",
    "config_sha256": "hash of the full generator config",
    "seed": "root seed of the dataset",
    "split": "train, validation or test",
    "colon_id": "procedural colon index, or the imported mesh's id",
    "colon_source": "the imported colon mesh by its manifest name; '' for a procedural colon",
    "colon_length_mm": "arc length of the GT centerline, mm",
    "n_samples": "rows of samples/",
}

#: Attributes a whole-colon shard carries only where they apply.
COLON_OPTIONAL_ATTRIBUTES = {
    "collapsed_mm": "JSON list of the imported colon's collapsed stretches [s0, s1] (mm of arc length: where its "
                    "lumen is narrower than the import's limit; their surface stays in the truth)",
}

#: Options of every dataset but the occupancies: gzip level 4 with shuffle, no timestamps.
COMPRESSION = {"compression": "gzip", "compression_opts": 4, "shuffle": True}
#: Options of the occupancy grids: one chunk per sample, gzip level 4 (level 9 saves 0.6 KiB a sample for 17 ms
#: of writing; decision 0417).
OCCUPANCY_COMPRESSION = {"compression": "gzip", "compression_opts": 4}


def field(path: str) -> Field:
    """The :class:`Field` stored at ``group/name``."""
    for f in FIELDS + HEATMAP_FIELDS:
        if f.path == path:
            return f
    raise KeyError(path)


def hole_model_dtype():
    """The HDF5 enum type of ``samples/hole_model``."""
    return h5py.enum_dtype(HOLE_MODEL_CODES, basetype="u1")


def describe(fields=FIELDS) -> list[tuple[str, str, str, str, str, str]]:
    """Rows ``(path, shape, dtype, unit, frame, description)`` for the docs, offsets included."""
    rows = []
    for f in fields:
        dims = [{"rows": "N" if f.group == "samples" else "M", "flat": "total"}.get(s, str(s)) for s in f.shape]
        shape = "(" + ", ".join(dims) + ("," if len(dims) == 1 else "") + ")"
        rows.append((f"`{f.path}`", shape, f.dtype, f.unit, f.frame, f.doc))
        if f.ragged:
            rows.append((f"`{f.path}_offsets`", "(N+1,)" if f.group == "samples" else "(M+1,)", "int64", "-", "-",
                         f"row i of `{f.name}` is `{f.name}[offsets[i]:offsets[i+1]]`"))
    return rows


def check(h5: h5py.File, deep: bool = True) -> list[str]:
    """Every way in which an open shard departs from the schema; an empty list when it conforms.

    Checks the attributes, the presence, dtype and shape of every field (of
    format 1 or 2), the offsets of ragged fields, that segment references and
    per-face masks line up, and that coverages are finite and within [0, 1];
    with ``deep``, one sample at a time, that format 1's heatmaps are within
    [0, 1] and that none of format 2's occupancy grids is empty.
    """
    if h5.attrs.get("format") == COLON_FORMAT:
        return check_colon(h5)
    faults = []
    for key in ATTRIBUTES:
        if key not in h5.attrs:
            faults.append(f"attribute {key!r} is missing")
    if faults:
        return faults
    if h5.attrs["format"] != FORMAT:
        return [f"attribute format is {h5.attrs['format']!r}, not {FORMAT!r}"]
    version = int(h5.attrs["format_version"])
    if version not in READ_VERSIONS:
        return [f"format_version {version} is not one this colonbench reads ({', '.join(map(str, READ_VERSIONS))}); "
                "a newer colonbench wrote it"]
    rows = {"samples": int(h5.attrs["n_samples"]), "segments": int(h5.attrs["n_segments"])}
    size = int(h5.attrs["grid_size"])
    quantized = version >= 2 and str(h5.attrs["split"]) in QUANTIZED_SPLITS
    offsets = {}
    for f in fields_of(version):
        if f.path not in h5:
            faults.append(f"{f.path} is missing")
            continue
        ds = h5[f.path]
        if not isinstance(ds, h5py.Dataset):
            faults.append(f"{f.path} is not a dataset")
            continue
        dtype = "int32" if f.quantized and quantized else f.dtype
        if ds.dtype != np.dtype(dtype):
            faults.append(f"{f.path} has dtype {ds.dtype}, expected {dtype}")
        elif f.quantized and quantized and not (ds.attrs.get("scale_mm") == POINT_SCALE_MM
                                       and np.shape(ds.attrs.get("offset_mm")) == (3,)):
            faults.append(f"{f.path} lacks its scale_mm ({POINT_SCALE_MM}) and offset_mm (3 values) attributes")
        n_flat = None
        if f.ragged:
            opath = f.path + "_offsets"
            if opath not in h5:
                faults.append(f"{opath} is missing")
                continue
            off = h5[opath][()]
            if off.shape != (rows[f.group] + 1,) or off.dtype != np.int64:
                faults.append(f"{opath} has shape {off.shape} {off.dtype}, expected ({rows[f.group] + 1},) int64")
                continue
            if off[0] != 0 or np.any(np.diff(off) < 0) or off[-1] != ds.shape[0]:
                faults.append(f"{opath} does not start at 0, rise, and end at the {ds.shape[0]} rows of {f.path}")
                continue
            offsets[f.path] = off
            n_flat = ds.shape[0]
        expected = tuple({"rows": rows[f.group], "S": size, "S^3/8": size ** 3 // 8, "flat": n_flat}.get(s, s)
                         for s in f.shape)
        if ds.shape != expected:
            faults.append(f"{f.path} has shape {ds.shape}, expected {expected}")
    if faults:
        return faults
    # a subset (colonbench.shards.subset) keeps data in these rows only; its other rows are emptied
    with_data = np.asarray(json.loads(h5.attrs["kept_samples"]), dtype=np.int64) \
        if "kept_samples" in h5.attrs else np.arange(rows["samples"])
    seg = h5["samples/segment"][()]
    if np.any((seg < 0) | (seg >= rows["segments"])):
        faults.append("samples/segment points outside segments/")
    else:
        n_faces = np.diff(offsets["segments/faces"])[seg]
        if not np.array_equal(np.diff(offsets["samples/observed_faces"])[with_data], n_faces[with_data]):
            faults.append("samples/observed_faces does not hold one value per face of each sample's segment")
    n_vert = np.diff(offsets["segments/vertices"])
    foff = offsets["segments/faces"]
    faces = h5["segments/faces"][()]
    for m in range(rows["segments"]):
        f = faces[foff[m]:foff[m + 1]]
        if len(f) and (f.min() < 0 or f.max() >= n_vert[m]):
            faults.append(f"segments/faces of segment row {m} index vertices it does not have")
    cov = h5["samples/coverage"][()]
    if not np.all(np.isfinite(cov) & (cov >= 0) & (cov <= 1)):
        faults.append("samples/coverage has values outside [0, 1]")
    if not deep:
        return faults
    for name in (("input", "target") if version == 1 else OCCUPANCIES):
        ds = h5["samples/" + name]
        for i in with_data.tolist():
            v = ds[i]
            if version == 1 and not (np.all(np.isfinite(v)) and v.min() >= 0 and v.max() <= 1):
                faults.append(f"samples/{name}[{i}] has values outside [0, 1]")
                break
            if version > 1 and not v.any():
                faults.append(f"samples/{name}[{i}] is empty (no occupied voxel: no heatmap can be made)")
                break
    return faults


def check_colon(h5: h5py.File) -> list[str]:
    """Every way in which an open whole-colon shard departs from :data:`COLON_FIELDS`; empty when it conforms."""
    faults = [f"attribute {key!r} is missing" for key in COLON_ATTRIBUTES if key not in h5.attrs]
    if faults:
        return faults
    if int(h5.attrs["format_version"]) != COLON_FORMAT_VERSION:
        return [f"format_version {int(h5.attrs['format_version'])} is not {COLON_FORMAT_VERSION}, the whole-colon "
                "version this colonbench reads"]
    n = int(h5.attrs["n_samples"])
    sizes = {}
    for f in COLON_FIELDS:
        if f.path not in h5 or not isinstance(h5[f.path], h5py.Dataset):
            faults.append(f"{f.path} is missing")
            continue
        ds = h5[f.path]
        if ds.dtype != np.dtype(f.dtype):
            faults.append(f"{f.path} has dtype {ds.dtype}, expected {f.dtype}")
        dims = {"rows": n, **sizes}
        if f.ragged:
            off = h5.get(f.path + "_offsets")
            if off is None or off.shape != (n + 1,) or off[0] != 0 or np.any(np.diff(off[()]) < 0) \
                    or off[-1] != ds.shape[0]:
                faults.append(f"{f.path}_offsets is missing or does not run from 0 to the {ds.shape[0]} rows of "
                              f"{f.path} in {n} rising steps")
                continue
            dims["flat"] = ds.shape[0]
        for k, s in enumerate(f.shape):  # V, F, C: the size the first dataset with that dimension has
            if s in ("V", "F", "C") and s not in dims:
                dims[s] = sizes[s] = ds.shape[k] if ds.ndim > k else -1
        expected = tuple(dims.get(s, s) for s in f.shape)
        if ds.shape != expected:
            faults.append(f"{f.path} has shape {ds.shape}, expected {expected}")
    if faults:
        return faults
    faces = h5["colon/faces"][()]
    if len(faces) == 0 or faces.min() < 0 or faces.max() >= h5["colon/vertices"].shape[0]:
        faults.append("colon/faces index vertices the colon does not have (or there are none)")
    cov = h5["samples/coverage"][()]
    if not np.all(np.isfinite(cov) & (cov >= 0) & (cov <= 1)):
        faults.append("samples/coverage has values outside [0, 1]")
    return faults
