"""Writing one shard file: buffered rows, per-sample heatmap chunks, atomic rename into place.

The writer follows :mod:`colonbench.shards.schema` and writes in a fixed
order with no timestamps, so the same rows give the same bytes.
"""

from __future__ import annotations

import os
from pathlib import Path

import h5py
import numpy as np

from colonbench.shards import schema

#: Suffix of files being written (``<shard>.tmp-<pid>``); never read as shards.
TMP_SUFFIX = ".tmp-"

_SEGMENT_FIELDS = tuple(f.name for f in schema.FIELDS if f.group == "segments")
_SAMPLE_FIELDS = tuple(f.name for f in schema.FIELDS if f.group == "samples" and f.name not in ("input", "target"))


def _ragged(rows, dtype, tail):
    """Flat array and int64 offsets of a list of arrays whose shapes end in ``tail``."""
    offsets = np.zeros(len(rows) + 1, dtype=np.int64)
    np.cumsum([len(r) for r in rows], out=offsets[1:])
    flat = np.concatenate([np.asarray(r).reshape((-1,) + tail) for r in rows]) if rows else np.zeros((0,) + tail)
    return flat.astype(dtype, copy=False), offsets


def publish(tmp: Path, path: Path) -> Path:
    """Flush a finished file written under ``tmp`` to disk and rename it to ``path`` (atomic on one file system)."""
    with open(tmp, "rb+") as fh:
        os.fsync(fh.fileno())
    os.replace(tmp, path)
    return path


class ShardWriter:
    """Write a shard under a temporary name; :meth:`close` renames it to ``path`` once complete.

    Parameters
    ----------
    path : path
        Final file name.
    n_samples : int
        Rows of ``samples/`` that will be added.
    size : int
        Heatmap grid side.

    Use as a context manager: an exception inside the block deletes the
    temporary file, and nothing appears under ``path``.
    """

    def __init__(self, path, n_samples: int, size: int):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.tmp = self.path.with_name(self.path.name + f"{TMP_SUFFIX}{os.getpid()}")
        self.n = int(n_samples)
        self.size = int(size)
        self.h5 = h5py.File(self.tmp, "w")
        self.h5.create_group("segments")
        self.h5.create_group("samples")
        self.heat = {name: self._dataset(f"samples/{name}", shape=(self.n,) + (self.size,) * 3,
                                         chunks=(1,) + (self.size,) * 3) for name in ("input", "target")}
        self.segments = {k: [] for k in _SEGMENT_FIELDS}
        self.samples = {k: [] for k in _SAMPLE_FIELDS}
        self.i = 0

    def _dataset(self, path, data=None, shape=None, chunks=True):
        f = schema.field(path)
        dtype = schema.hole_model_dtype() if path == "samples/hole_model" else np.dtype(f.dtype)
        if data is not None:
            data = np.asarray(data).astype(dtype, copy=False)
            shape = data.shape
        opts = dict(schema.COMPRESSION) if 0 not in shape else {}
        ds = self.h5.create_dataset(path, shape=shape, dtype=dtype, chunks=chunks if opts else None,
                                    track_times=False, **opts)
        if data is not None and data.size:
            ds[...] = data
        # write the chunks out now: when HDF5 allocates their file space must not depend on when Python
        # happens to release the dataset object (garbage collection timing differs between processes)
        ds.flush()
        return ds

    def add_segment(self, **fields):
        """Append one row of ``segments/``: every segments field of the schema, by name."""
        missing = sorted(set(_SEGMENT_FIELDS) - set(fields))
        if missing or set(fields) - set(_SEGMENT_FIELDS):
            raise ValueError(f"segment row needs exactly {_SEGMENT_FIELDS}; missing {missing}")
        for k, v in fields.items():
            self.segments[k].append(v)
        return len(self.segments["segment_id"]) - 1

    def add_sample(self, input, target, **fields):
        """Append one row of ``samples/``: the two (S, S, S) heatmaps and every other samples field, by name."""
        missing = sorted(set(_SAMPLE_FIELDS) - set(fields))
        if missing or set(fields) - set(_SAMPLE_FIELDS):
            raise ValueError(f"sample row needs exactly {_SAMPLE_FIELDS}; missing {missing}")
        if self.i >= self.n:
            raise ValueError(f"this shard was opened for {self.n} samples")
        for name, value in (("input", input), ("target", target)):
            self.heat[name][self.i] = np.asarray(value).astype(np.float16)
            self.heat[name].flush()
        for k, v in fields.items():
            self.samples[k].append(v)
        self.i += 1

    def _write_group(self, group, rows):
        for name, values in rows.items():
            f = schema.field(f"{group}/{name}")
            if f.ragged:
                flat, offsets = _ragged(values, f.dtype, tuple(s for s in f.shape[1:]))
                chunks = (min(len(flat), 65536),) + flat.shape[1:] if len(flat) else None
                self._dataset(f.path, flat, chunks=chunks)
                self.h5.create_dataset(f.path + "_offsets", data=offsets, track_times=False).flush()
            else:
                self._dataset(f.path, np.asarray(values).reshape((len(values),) + tuple(f.shape[1:])))

    def close(self, attrs: dict) -> Path:
        """Write the buffered rows and the file attributes, flush, and rename into place."""
        if self.i != self.n:
            raise ValueError(f"{self.i} samples added to a shard opened for {self.n}")
        self._write_group("segments", self.segments)
        self._write_group("samples", self.samples)
        for key in schema.ATTRIBUTES:
            if key not in attrs:
                raise ValueError(f"shard attribute {key!r} missing")
        for key, val in attrs.items():
            self.h5.attrs[key] = val
        self.h5.close()
        return publish(self.tmp, self.path)

    def abort(self):
        """Close and delete the temporary file."""
        try:
            self.h5.close()
        finally:
            if self.tmp.exists():
                self.tmp.unlink()

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is not None:
            self.abort()
        elif self.tmp.exists():
            self.abort()  # close() was never called: nothing is published
            raise RuntimeError(f"ShardWriter for {self.path} left without close()")
