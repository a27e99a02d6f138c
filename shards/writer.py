"""Writing one shard file: buffered rows, per-sample occupancy chunks, atomic rename into place.

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
_PER_SAMPLE = schema.OCCUPANCIES + ("input", "target")
_SAMPLE_FIELDS = tuple(f.name for f in schema.FIELDS if f.group == "samples" and f.name not in _PER_SAMPLE)


def _ragged(rows, dtype, tail):
    """Flat array and int64 offsets of a list of arrays whose shapes end in ``tail``."""
    offsets = np.zeros(len(rows) + 1, dtype=np.int64)
    np.cumsum([len(r) for r in rows], out=offsets[1:])
    flat = np.concatenate([np.asarray(r).reshape((-1,) + tail) for r in rows]) if rows else np.zeros((0,) + tail)
    return flat.astype(dtype, copy=False), offsets


def quantize_points(flat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points (k, 3) mm as int32 multiples of :data:`schema.POINT_SCALE_MM` from an integer-mm offset.

    Returns
    -------
    q : (k, 3) int32
    offset_mm : (3,) float64
        ``mm = q * POINT_SCALE_MM + offset_mm`` (:func:`colonbench.shards.reader.decode_points`) is within
        half a step of the input, plus float rounding.
    """
    x = np.asarray(flat, dtype=np.float64).reshape(-1, 3)
    if not np.isfinite(x).all():
        raise ValueError(f"{int((~np.isfinite(x).all(axis=1)).sum())} point(s) are NaN or infinite: they have no "
                         "micrometre value")
    offset = np.floor(x.min(axis=0)) if len(x) else np.zeros(3)
    q = np.rint((x - offset) / schema.POINT_SCALE_MM)
    if len(q) and q.max() >= 2 ** 31:
        raise ValueError(f"points span {q.max() * schema.POINT_SCALE_MM:.0f} mm: too far for int32 micrometres")
    return q.astype(np.int32), offset


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
        Grid side S.
    version : int
        Shard format: 2 stores the occupancy grids (bit-packed), 1 the float16
        heatmaps (format 1 is written only to compare the two).
    quantize : bool
        Store the point sets (:attr:`schema.Field.quantized`) as int32
        micrometres (the ``train`` and ``validation`` splits of format 2).

    Use as a context manager: an exception inside the block deletes the
    temporary file, and nothing appears under ``path``.
    """

    def __init__(self, path, n_samples: int, size: int, version: int = schema.FORMAT_VERSION, quantize: bool = False):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.tmp = self.path.with_name(self.path.name + f"{TMP_SUFFIX}{os.getpid()}")
        self.n = int(n_samples)
        self.size = int(size)
        self.h5 = h5py.File(self.tmp, "w")
        self.h5.create_group("segments")
        self.h5.create_group("samples")
        self.version, self.quantize = int(version), bool(quantize and version >= 2)
        if self.version == 1:  # 2 MiB per sample: written as it comes
            self.grids = {name: self._dataset(f"samples/{name}", shape=(self.n,) + (self.size,) * 3,
                                              chunks=(1,) + (self.size,) * 3) for name in ("input", "target")}
        else:  # 96 KiB per sample (3 x 64^3 bits): kept, and written at close in one go (a flush per sample: 6 ms)
            self.grids = {name: np.zeros((self.n, self.size ** 3 // 8), np.uint8) for name in schema.OCCUPANCIES}
        self.segments = {k: [] for k in _SEGMENT_FIELDS}
        self.samples = {k: [] for k in _SAMPLE_FIELDS}
        self.i = 0

    def _dataset(self, path, data=None, shape=None, chunks=True, opts=schema.COMPRESSION):
        f = schema.field(path)
        dtype = schema.hole_model_dtype() if path == "samples/hole_model" else np.dtype(f.dtype)
        if data is not None:
            dtype = np.int32 if np.asarray(data).dtype == np.int32 and f.quantized else dtype
            data = np.asarray(data).astype(dtype, copy=False)
            shape = data.shape
        opts = dict(opts) if 0 not in shape else {}
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

    def add_sample(self, grids: dict, **fields):
        """Append one row of ``samples/``: its grids and every other samples field, by name.

        ``grids``: format 2, ``s0``, ``s1``, ``c`` as (S^3 / 8,) uint8
        (:func:`colonbench.heatmaps.pack_occupancy`); format 1, ``input`` and
        ``target`` (S, S, S) heatmaps.
        """
        missing = sorted(set(_SAMPLE_FIELDS) - set(fields))
        if missing or set(fields) - set(_SAMPLE_FIELDS):
            raise ValueError(f"sample row needs exactly {_SAMPLE_FIELDS}; missing {missing}")
        if set(grids) != set(self.grids):
            raise ValueError(f"a format-{self.version} sample row needs the grids {sorted(self.grids)}")
        if self.i >= self.n:
            raise ValueError(f"this shard was opened for {self.n} samples")
        for name, value in grids.items():
            dtype = np.float16 if self.version == 1 else np.uint8
            self.grids[name][self.i] = np.asarray(value).astype(dtype, copy=False)
            if self.version == 1:
                self.grids[name].flush()
        for k, v in fields.items():
            self.samples[k].append(v)
        self.i += 1

    def _write_group(self, group, rows):
        for name, values in rows.items():
            f = schema.field(f"{group}/{name}")
            if f.ragged:
                flat, offsets = _ragged(values, f.dtype, tuple(s for s in f.shape[1:]))
                offset_mm = None
                if f.quantized and self.quantize:
                    flat, offset_mm = quantize_points(flat)
                chunks = (min(len(flat), 65536),) + flat.shape[1:] if len(flat) else None
                ds = self._dataset(f.path, flat, chunks=chunks)
                if offset_mm is not None:
                    ds.attrs["scale_mm"] = schema.POINT_SCALE_MM
                    ds.attrs["offset_mm"] = offset_mm
                self.h5.create_dataset(f.path + "_offsets", data=offsets, track_times=False).flush()
            else:
                self._dataset(f.path, np.asarray(values).reshape((len(values),) + tuple(f.shape[1:])))

    def close(self, attrs: dict) -> Path:
        """Write the buffered rows and the file attributes, flush, and rename into place."""
        if self.i != self.n:
            raise ValueError(f"{self.i} samples added to a shard opened for {self.n}")
        if self.version > 1:
            row = self.size ** 3 // 8
            for name in schema.OCCUPANCIES:
                self._dataset(f"samples/{name}", self.grids[name], chunks=(1, row), opts=schema.OCCUPANCY_COMPRESSION)
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
