"""A copy of a shard that holds only some of its samples: what a suite archive carries.

The copy keeps the schema and every row, so that a sample keeps its index (and
its sample id) and every reader works on it unchanged; the rows that are not
kept are emptied: their point sets, masks and meshes have no entries and their
occupancy grids (format 1: heatmaps) are never written (HDF5 stores no chunk
for them; they read as 0).
Segments that no kept sample uses are emptied the same way. The file attribute
``kept_samples`` (a JSON list of the kept row indices) says which rows hold data, and a dataset lock that
lists subsets names them under ``kept_samples`` too, so that every reader of the folder
(:func:`colonbench.benchmark.evaluate.select`) takes only those rows.
"""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np

from colonbench.errors import InputError
from colonbench.shards import schema
from colonbench.shards.writer import TMP_SUFFIX, publish

#: File attribute of a subset: JSON list of the sample rows that hold data (absent in a whole shard).
KEPT_ATTR = "kept_samples"


def _copy_ragged(src: h5py.Group, dst: h5py.Group, name: str, keep: np.ndarray) -> None:
    """Copy ragged field ``name`` with the rows not in the boolean ``keep`` emptied."""
    flat, offsets = src[name], src[name + "_offsets"][()]
    counts = np.diff(offsets) * keep
    new_offsets = np.zeros_like(offsets)
    np.cumsum(counts, out=new_offsets[1:])
    rows = [flat[offsets[r]:offsets[r + 1]] for r in np.flatnonzero(keep)]
    data = np.concatenate(rows) if rows else np.zeros((0,) + flat.shape[1:], flat.dtype)
    opts = dict(schema.COMPRESSION) if len(data) else {}
    chunks = (min(len(data), 65536),) + data.shape[1:] if len(data) else None
    out = dst.create_dataset(name, data=data.astype(flat.dtype, copy=False), chunks=chunks, track_times=False, **opts)
    for key, value in flat.attrs.items():  # a quantized point set's scale and offset
        out.attrs[key] = value
    dst.create_dataset(name + "_offsets", data=new_offsets, track_times=False)


def write_subset(src, dst, samples) -> Path:
    """Write a copy of shard ``src`` at ``dst`` holding only the sample rows ``samples`` (the rest emptied).

    Parameters
    ----------
    src, dst : path
        A segment shard (:mod:`colonbench.shards.schema`) and where its subset goes (written under a temporary
        name, then renamed).
    samples : iterable of int
        Rows of ``samples/`` to keep.

    Returns
    -------
    Path
        ``dst``.
    """
    dst = Path(dst)
    dst.parent.mkdir(parents=True, exist_ok=True)
    tmp = dst.with_name(dst.name + f"{TMP_SUFFIX}subset")
    with h5py.File(src, "r") as a:
        if a.attrs.get("format") != schema.FORMAT:
            raise InputError(f"{src}: a subset is made of a segment shard ({schema.FORMAT}), not of "
                             f"{a.attrs.get('format')!r}")
    with h5py.File(src, "r") as a, h5py.File(tmp, "w") as b:
        n = int(a.attrs["n_samples"])
        keep = np.zeros(n, bool)
        keep[list(samples)] = True
        seg_keep = np.zeros(int(a.attrs["n_segments"]), bool)
        seg_keep[a["samples/segment"][()][keep]] = True
        for group, rows in (("segments", seg_keep), ("samples", keep)):
            g = b.create_group(group)
            for f in schema.fields_of(int(a.attrs["format_version"])):
                if f.group != group or f.path not in a:
                    continue
                ds = a[f.path]
                if f.ragged:
                    _copy_ragged(a[group], g, f.name, rows)
                elif f.name in ("input", "target") + schema.OCCUPANCIES:
                    opts = schema.COMPRESSION if f.name in ("input", "target") else schema.OCCUPANCY_COMPRESSION
                    out = g.create_dataset(f.name, shape=ds.shape, dtype=ds.dtype, chunks=ds.chunks,
                                           track_times=False, **opts)
                    for r in np.flatnonzero(rows):
                        out[r] = ds[r]
                else:
                    a.copy(ds, g, name=f.name)
        for key, value in a.attrs.items():
            b.attrs[key] = value
        b.attrs[KEPT_ATTR] = json.dumps([int(i) for i in np.flatnonzero(keep)])
    return publish(tmp, dst)
