"""Reading shards: one sample at a time, lazily, safe to hand to PyTorch ``DataLoader`` workers.

Files are opened on first access in the process that reads them (never
inherited through ``fork`` or pickling), so a :class:`ShardDataset` can be
passed to a ``torch.utils.data.DataLoader`` with any number of workers. It
returns numpy arrays, which the default collate function turns into tensors;
PyTorch itself is not needed here.

Example
-------
>>> ds = ShardDataset("data/paper", split="train")          # doctest: +SKIP
>>> item = ds[0]; item["input"].shape                       # doctest: +SKIP
(1, 64, 64, 64)
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import h5py
import numpy as np

from colonbench import seeding
from colonbench.errors import InputError
from colonbench.grid import Grid
from colonbench.shards import schema
from colonbench.shards.schema import LOCK_NAME


def decode_points(ds: h5py.Dataset, rows: np.ndarray) -> np.ndarray:
    """Rows of a point set as float32 mm: int32 micrometres (a training split's) decoded, float32 as stored."""
    if "scale_mm" not in ds.attrs:
        return rows
    if "offset_mm" not in ds.attrs:
        raise InputError(f"{ds.file.filename}: {ds.name} is in micrometres but has no offset_mm attribute; the shard "
                         "is damaged (colonbench verify)")
    scale, offset = float(ds.attrs["scale_mm"]), np.asarray(ds.attrs["offset_mm"], dtype=np.float64)
    return (rows * scale + offset).astype(np.float32)


def format1_occupancy(input_heatmap: np.ndarray, target_heatmap: np.ndarray, centerline: np.ndarray) -> dict:
    """The three occupancy grids of a format-1 sample from its stored heatmaps and its voxelized centerline.

    Parameters
    ----------
    input_heatmap, target_heatmap : (S, S, S) float
        As format 1 stored them.
    centerline : (S, S, S) bool
        The voxelized GT centerline, as generation made it
        (:func:`colonbench.heatmaps.voxelize_polyline` on the sample's grid).

    Returns
    -------
    dict
        ``s0``, ``s1``, ``c``: (S, S, S) bool.

    Notes
    -----
    The centerline is not read from the target (``== 1``): a centerline
    voxel that is also a surface voxel has target 0, and the widened
    generator makes such voxels (a stalked polyp's head or a flattened
    section across the centerline); without them the centerline's distances,
    and so the target, come out otherwise.
    """
    return {"s0": input_heatmap == 0, "s1": target_heatmap == 0, "c": np.asarray(centerline, dtype=bool)}


def ragged_row(group, name: str, i: int) -> np.ndarray:
    """Row ``i`` of the ragged field ``name`` of an open HDF5 group (through ``<name>_offsets``); point sets
    stored as micrometres come back as float32 mm (:func:`decode_points`)."""
    off = group[name + "_offsets"]
    a, b = int(off[i]), int(off[i + 1])
    ds = group[name]
    return decode_points(ds, ds[a:b])


def read_attrs(path: Path) -> dict:
    """The file attributes of an HDF5 file as Python values, or an :class:`InputError` if it cannot be read."""
    try:
        with h5py.File(path, "r") as h5:
            return {k: (v.item() if hasattr(v, "item") else v) for k, v in h5.attrs.items()}
    except OSError as exc:
        raise InputError(f"{path}: not a readable HDF5 file ({exc})") from None


class Shard:
    """One shard file, opened lazily.

    Parameters
    ----------
    path : path
        A ``.h5`` shard.
    """

    def __init__(self, path):
        self.path = Path(path)
        self._h5 = None
        self._pid = None
        self.attrs = read_attrs(self.path)
        if self.attrs.get("format") != schema.FORMAT:
            raise InputError(f"{self.path}: not a colonbench shard")
        self.version = int(self.attrs.get("format_version", -1))
        if self.version not in schema.READ_VERSIONS:
            raise InputError(f"{self.path}: shard format version {self.attrs.get('format_version')}; this colonbench "
                             f"reads versions {', '.join(map(str, schema.READ_VERSIONS))} (a newer one wrote it)")

    @property
    def h5(self) -> h5py.File:
        """The open file (opened in this process on first use)."""
        if self._h5 is None or self._pid != os.getpid():
            self._h5 = h5py.File(self.path, "r")
            self._pid = os.getpid()
        return self._h5

    def __len__(self) -> int:
        return int(self.attrs["n_samples"])

    def close(self):
        if self._h5 is not None and self._pid == os.getpid():
            self._h5.close()
        self._h5 = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __getstate__(self):
        state = dict(self.__dict__)
        state["_h5"] = None
        state["_pid"] = None
        return state

    def _check(self, i: int) -> int:
        if not -len(self) <= i < len(self):
            raise IndexError(f"{self.path}: sample {i} out of range ({len(self)} samples)")
        return i % len(self)

    @property
    def grid_options(self) -> dict:
        """``size``, ``margin``, ``min_extent_mm`` and ``axes`` the grids of this shard were fitted with."""
        return {"size": int(self.attrs["grid_size"]), "margin": int(self.attrs["grid_margin"]),
                "min_extent_mm": float(self.attrs["grid_min_extent_mm"]),
                "axes": str(self.attrs.get("grid_axes", "pca"))}

    def heatmaps(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """(input, target), each (S, S, S) float32, of sample ``i``.

        Format 1 stored them; format 2 stores the occupancy grids and they are
        made here (:func:`colonbench.heatmaps.heatmaps_from_occupancy`, three
        ``edt`` distance transforms), rounded to float16 as format 1 stored
        them, so both formats give the same values.
        """
        i = self._check(i)
        smp = self.h5["samples"]
        if self.version == 1:
            return smp["input"][i].astype(np.float32), smp["target"][i].astype(np.float32)
        from colonbench.heatmaps import empty_grids, heatmaps_from_occupancy

        occ = self.occupancy(i)
        empty = empty_grids(occ)
        if empty:
            raise InputError(f"{self.path}: sample {i} has an empty {' and '.join(empty)} grid, so no heatmap can be "
                             "made (a row a subset does not keep, or a damaged shard: colonbench verify)")
        return tuple(h.astype(np.float16).astype(np.float32) for h in heatmaps_from_occupancy(
            occ["s0"], occ["s1"], occ["c"]))

    def occupancy_bits(self, i: int) -> dict:
        """``s0``, ``s1``, ``c`` of sample ``i`` as stored in format 2: (S^3 / 8,) uint8, bit-packed."""
        i = self._check(i)
        if self.version == 1:
            from colonbench.heatmaps import pack_occupancy

            return {k: pack_occupancy(v) for k, v in self.occupancy(i).items()}
        smp = self.h5["samples"]
        return {name: smp[name][i] for name in schema.OCCUPANCIES}

    def occupancy(self, i: int, heatmaps=None) -> dict:
        """``s0``, ``s1``, ``c`` of sample ``i``: (S, S, S) bool, the grids its heatmaps are functions of.

        Format 1 stored no occupancy: they are read off its stored heatmaps
        (:func:`format1_occupancy`; pass them as ``heatmaps`` where they
        were read already).
        """
        i = self._check(i)
        if self.version == 1:
            from colonbench.heatmaps import voxelize_polyline

            x, y = self.heatmaps(i) if heatmaps is None else heatmaps
            return format1_occupancy(x, y, voxelize_polyline(self.grid(i), self.centerline(i))[0])
        from colonbench.heatmaps import unpack_occupancy

        size = int(self.attrs["grid_size"])
        return {k: unpack_occupancy(v, size) for k, v in self.occupancy_bits(i).items()}

    def grid(self, i: int) -> Grid:
        """The :class:`~colonbench.grid.Grid` of sample ``i``'s heatmaps."""
        i = self._check(i)
        return Grid(self.h5["samples/grid_affine"][i], int(self.attrs["grid_size"]))

    def centerline(self, i: int) -> np.ndarray:
        """(m, 3) float: the GT centerline of sample ``i``'s segment, mm (without reading its mesh)."""
        i = self._check(i)
        return ragged_row(self.h5["segments"], "centerline", int(self.h5["samples/segment"][i])).astype(float)

    def segment(self, m: int) -> dict:
        """Segment row ``m``: ``segment_id``, ``window_mm``, ``complete_area_mm2``, ``vertices``, ``faces``, ``centerline``."""
        seg = self.h5["segments"]
        return {"segment_id": int(seg["segment_id"][m]), "window_mm": seg["window_mm"][m],
                "complete_area_mm2": float(seg["complete_area_mm2"][m]), "vertices": ragged_row(seg, "vertices", m),
                "faces": ragged_row(seg, "faces", m), "centerline": ragged_row(seg, "centerline", m)}

    def geometry(self, i: int) -> dict:
        """Sample ``i`` without heatmaps: points, its segment's mesh and centerline, GT values, ids (mm)."""
        i = self._check(i)
        smp = self.h5["samples"]
        m = int(smp["segment"][i])
        out = {"shard": self.path.name, "index": i, "split": self.attrs["split"],
               "colon_id": int(self.attrs["colon_id"]), "length_mm": float(self.attrs["length_mm"]),
               "permutation": int(smp["permutation"][i]), "hole_model": schema.HOLE_MODEL_NAMES[int(smp["hole_model"][i])],
               "noise_mm": float(smp["noise_mm"][i]), "coverage": float(smp["coverage"][i]),
               "outside_grid": float(smp["outside_grid"][i]), "grid_affine": smp["grid_affine"][i],
               "partial_points": ragged_row(smp, "partial_points", i), "hole_points": ragged_row(smp, "hole_points", i),
               "observed_faces": ragged_row(smp, "observed_faces", i).astype(bool),
               "hole_areas_mm2": ragged_row(smp, "hole_areas_mm2", i)}
        out.update(self.segment(m))
        return out

    def sample(self, i: int) -> dict:
        """Every stored field of sample ``i``: :meth:`geometry`, ``input`` and ``target`` (S, S, S) float32
        (:meth:`heatmaps`) and, in format 2, the stored grids ``s0``, ``s1``, ``c`` (:meth:`occupancy_bits`)."""
        out = self.geometry(i)
        out["input"], out["target"] = self.heatmaps(i)
        if self.version > 1:
            out.update(self.occupancy_bits(i))
        return out


def available_memory_mib() -> float:
    """Memory available to new allocations, MiB (Linux ``MemAvailable``; 0 where it cannot be read)."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    return 0.0


def dataset_files(root, split=None) -> list[Path]:
    """The shard files of a dataset folder (from its lock, in order), optionally of one split."""
    root = Path(root)
    lock = root / LOCK_NAME
    if not lock.exists():
        raise InputError(f"{root}: no {LOCK_NAME}; generate the dataset first (colonbench generate)")
    shards = json.loads(lock.read_text())["shards"]
    files = [root / name for name, e in shards.items() if split is None or e["split"] == split]
    if not files:
        raise InputError(f"{root}: no shards" + (f" of split {split!r}" if split else ""))
    return files


class ShardSamples:
    """The samples of a dataset folder (or of shard files) as one sequence: ``len``, ``locate(k)`` and the epoch.

    The base of :class:`ShardDataset` (heatmaps) and
    :class:`colonbench.shards.pointclouds.PointCloudDataset` (point clouds).

    Parameters
    ----------
    source : path or list of paths
        A dataset folder (its lock lists the shards) or shard files.
    split : str, optional
        Only this split of a dataset folder.
    """

    def __init__(self, source, split=None):
        if isinstance(source, (str, os.PathLike)) and Path(source).is_dir():
            files = dataset_files(source, split)
        else:
            files = [Path(source)] if isinstance(source, (str, os.PathLike)) else [Path(p) for p in source]
        self.shards = [Shard(f) for f in files]
        self.offsets = np.concatenate([[0], np.cumsum([len(s) for s in self.shards])]).astype(np.int64)
        self.epoch = 0

    def __len__(self) -> int:
        return int(self.offsets[-1])

    def set_epoch(self, epoch: int):
        """Choose the random draws of this epoch (a non-negative whole number)."""
        if int(epoch) < 0:
            raise InputError(f"{type(self).__name__}: epoch must be non-negative, got {epoch}")
        self.epoch = int(epoch)

    def locate(self, k: int) -> tuple[Shard, int]:
        """The shard and local index of item ``k``."""
        if not -len(self) <= k < len(self):
            raise IndexError(f"item {k} out of range ({len(self)} items)")
        k %= len(self)
        s = int(np.searchsorted(self.offsets, k, side="right") - 1)
        return self.shards[s], int(k - self.offsets[s])

    def close(self):
        for s in self.shards:
            s.close()


class ShardDataset(ShardSamples):
    """A map-style dataset over shards: ``ds[k]`` is one sample's heatmaps (and optionally its geometry).

    Parameters
    ----------
    source : path or list of paths
        A dataset folder (its lock lists the shards) or shard files.
    split : str, optional
        Only this split of a dataset folder.
    geometry : bool
        Also return :meth:`Shard.geometry` fields (variable-size arrays: use
        a custom collate function or batch size 1).
    augment : colonbench.augment.AugmentConfig, optional
        Remake the heatmaps from augmented geometry on every access
        (:func:`colonbench.augment.augmented_heatmaps`). The draw for item
        ``k`` in epoch ``e`` comes from stream ``("augment", e, k)`` under
        ``seed``: the same whatever worker reads it.
    seed : int
        Root seed of the augmentation streams.
    augment_prob : float
        Share of items augmented (drawn per item from the same stream); the
        others return their stored heatmaps.
    cache_mib : float or "auto"
        Keep the heatmaps made from format-2 occupancies (float16, 1 MiB per
        sample at S = 64) in this process, up to this much memory, so that
        later epochs do not make them again; ``"auto"``: an eighth of the
        memory available when the dataset is made, at most 4 GiB. DataLoader
        workers each keep their own, with an equal share of it. 0: none.

    Items
    -----
    dict with ``input`` and ``target`` (1, S, S, S) float32 (a channel axis
    first, as PyTorch's 3D convolutions expect), ``coverage`` float and
    ``index`` int, plus the geometry fields if asked.
    """

    def __init__(self, source, split=None, geometry: bool = False, augment=None, seed: int = 0,
                 augment_prob: float = 1.0, cache_mib="auto"):
        super().__init__(source, split)
        self.geometry = geometry
        self.augment = augment
        self.seed = int(seed)
        self.augment_prob = float(augment_prob)
        if cache_mib == "auto":
            cache_mib = min(4096.0, available_memory_mib() / 8)
        if not isinstance(cache_mib, (int, float)) or not cache_mib >= 0:
            raise InputError(f"cache_mib: a size in MiB (0 or more) or 'auto', not {cache_mib!r}")
        self.cache_mib = float(cache_mib)
        self._cache = {}

    def __getstate__(self):
        state = dict(self.__dict__)
        state["_cache"] = {}  # a worker process makes its own
        return state

    def _cache_budget(self) -> float:
        """MiB this process may keep: ``cache_mib`` shared out among a DataLoader's worker processes."""
        torch_data = sys.modules.get("torch.utils.data")
        info = torch_data.get_worker_info() if torch_data is not None else None
        return self.cache_mib / (info.num_workers if info is not None else 1)

    def stored_heatmaps(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """(input, target) (S, S, S) float32 of item ``k`` without augmentation, from the cache where kept."""
        shard, i = self.locate(k)
        k = int(k % len(self))
        if k in self._cache:
            return tuple(h.astype(np.float32) for h in self._cache[k])
        h_in, h_t = shard.heatmaps(i)
        if shard.version > 1 and (len(self._cache) + 1) * 2 * h_in.size * 2 <= self._cache_budget() * 2 ** 20:
            self._cache[k] = (h_in.astype(np.float16), h_t.astype(np.float16))
        return h_in, h_t

    def __getitem__(self, k: int) -> dict:
        shard, i = self.locate(k)
        item = {"index": int(k % len(self))}
        rng = seeding.rng(self.seed, "augment", self.epoch, item["index"]) if self.augment is not None else None
        augment = rng is not None and (self.augment_prob >= 1.0 or rng.random() < self.augment_prob)
        geo = shard.geometry(i) if (self.geometry or augment) else None
        if augment:
            from colonbench.augment import augmented_heatmaps
            _, hm = augmented_heatmaps(rng, geo["partial_points"].astype(float), geo["vertices"].astype(float),
                                       geo["faces"], geo["centerline"].astype(float), self.augment,
                                       shard.grid_options)
            h_in, h_t = hm.input, hm.target
        else:
            h_in, h_t = self.stored_heatmaps(k)
        item["input"] = h_in[None].astype(np.float32, copy=False)
        item["target"] = h_t[None].astype(np.float32, copy=False)
        item["coverage"] = float(shard.h5["samples/coverage"][i])
        if self.geometry:
            item.update({k: v for k, v in geo.items() if k not in item})
        return item
