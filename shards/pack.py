"""Packs: a generated dataset's training samples as compact voxel occupancies, for training elsewhere.

A sample's heatmaps are functions of three occupancy grids (:mod:`colonbench.heatmaps`):

``s0``
    voxels holding a partial point (where the input heatmap is 0);
``s1``
    voxels the complete surface passes through (where the target is 0);
``c``
    voxels the GT centerline passes through (voxelized again from the
    shard's centerline polyline: where it crosses the surface the target
    is 0, not 1).

Format-2 shards store them beside the geometry (about 130 KiB per sample);
a pack is their view without the geometry: the same bit-packed grids (about
5 KiB per sample), so that tens of thousands of samples travel to a GPU
machine in one upload and the heatmaps are made there with exact distance
transforms (:mod:`colonbench.completion.packdata`). Training reads the same
grids from format-2 shards directly (:func:`read_shard_bits`); a pack is
only for carrying. It cannot hold the geometry, so the geometric
augmentations (:mod:`colonbench.augment`) need shards; a pack supports only
the exact symmetries of the grid (axis flips, transposes).

Layout of a pack folder::

    pack.json          what it was made from (manifest sha256, grid options,
                       train coverage mean), per split its sample count and
                       its file's sha256
    <split>.h5         datasets s0, s1, c: (n, S^3 / 8) uint8, numpy.packbits
                       of the (S, S, S) bool grid in C order; gzip level 9,
                       one chunk per sample

``colonbench pack DATA --out PACK`` writes one, from format-2 shards by
copying their grids, from format-1 shards (which stored heatmaps) by reading
the grids off the heatmaps, each sample checked: the heatmaps recomputed from
the occupancies must equal the stored ones to float16 rounding.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import h5py
import numpy as np

from colonbench._version import __version__
from colonbench.errors import InputError
from colonbench.shards.schema import LOCK_NAME, sha256_file

#: The description file of a pack folder.
PACK_NAME = "pack.json"
#: Value of ``format`` in it.
PACK_FORMAT = "colonbench-pack"
#: Bumped whenever the layout changes.
PACK_VERSION = 1
#: The occupancy grids a pack stores per sample, in this order.
GRIDS = ("s0", "s1", "c")
#: The fourth grid of a context pack (:mod:`colonbench.mapping.contextpack`): the segment's slab
#: (:func:`colonbench.slab.slab_occupancy`), the in-context model's second input channel.
SLAB = "slab"
#: Largest difference between a stored (float16) heatmap and the one recomputed from the occupancies.
CHECK_TOLERANCE = 2e-3


def is_pack(path) -> bool:
    """Whether ``path`` is a pack folder."""
    return (Path(path) / PACK_NAME).is_file()


def _pack_shard(path) -> tuple[dict, float]:
    """Packed occupancies (``GRIDS`` -> (n, S^3 / 8) uint8) of one shard, and the largest heatmap difference
    (format 1: the stored heatmaps against those remade from the grids read off them; format 2: 0)."""
    from colonbench.heatmaps import empty_grids, heatmaps_from_occupancy, pack_occupancy
    from colonbench.shards.reader import Shard

    rows = {g: [] for g in GRIDS}
    worst = 0.0
    with Shard(path) as shard:
        if shard.version > 1:  # the grids as stored: a pack is their view
            return _stored_bits(shard), 0.0
        for i in range(len(shard)):
            x, y = shard.heatmaps(i)
            occ = shard.occupancy(i, heatmaps=(x, y))
            empty = empty_grids(occ)
            if empty:
                raise InputError(f"{path}: sample {i} has an empty {' and '.join(empty)} grid; the dataset is damaged "
                                 "(run colonbench verify)")
            h_in, h_t = heatmaps_from_occupancy(occ["s0"], occ["s1"], occ["c"])
            worst = max(worst, float(np.abs(h_in - x).max()), float(np.abs(h_t - y).max()))
            for g in GRIDS:
                rows[g].append(pack_occupancy(occ[g]))
    return {g: np.stack(r) for g, r in rows.items()}, worst


def dataset_lock(data_dir: Path, splits) -> dict:
    """A generated dataset's lock file, checked to hold ``splits``; an :class:`InputError` otherwise."""
    lock_path = Path(data_dir) / LOCK_NAME
    if not lock_path.is_file():
        raise InputError(f"{data_dir}: no {LOCK_NAME}; generate the dataset first (colonbench generate)")
    lock = json.loads(lock_path.read_text())
    missing = [s for s in splits if s not in lock.get("splits", {})]
    if missing:
        raise InputError(f"{data_dir}: the dataset has no split {', '.join(missing)} "
                         f"(it has {', '.join(lock.get('splits', {})) or 'none'})")
    return lock


def write_pack(data_dir, out_dir, splits=("train", "validation"), workers: int = 1, progress: bool = True) -> dict:
    """Write the pack of a generated dataset's splits.

    Parameters
    ----------
    data_dir : path
        A dataset folder made by ``colonbench generate``.
    out_dir : path
        The pack folder to write (created; an existing pack of other data is refused).
    splits : sequence of str
    workers : int
        Processes reading and checking shards (spawn pool; 1 = this process).
    progress : bool
        A progress bar (:mod:`colonbench.progress`).

    Returns
    -------
    dict
        The contents of ``pack.json``.
    """
    from colonbench.shards.reader import ShardDataset

    data_dir, out = Path(data_dir), Path(out_dir)
    lock = dataset_lock(data_dir, splits)
    info = {"format": PACK_FORMAT, "format_version": PACK_VERSION, "colonbench": __version__,
            "manifest_name": lock.get("manifest_name"), "manifest_sha256": lock["manifest_sha256"],
            "source": data_dir.name, "splits": {}}
    if is_pack(out):  # add to it: the splits packed before stay
        old = json.loads((out / PACK_NAME).read_text())
        if old.get("manifest_sha256") != lock["manifest_sha256"] or old.get("format_version") != PACK_VERSION:
            raise InputError(f"{out} holds a pack of other data ({old.get('manifest_name')}); use another --out")
        info["splits"] = old.get("splits", {})
        info.update({k: old[k] for k in ("grid_options", "train_coverage_mean") if k in old})
    out.mkdir(parents=True, exist_ok=True)
    for split in splits:
        ds = ShardDataset(data_dir, split=split)
        n = len(ds)
        if n == 0:
            raise InputError(f"{data_dir}: split {split} has no samples")
        size = ds.shards[0].grid_options["size"]
        info["grid_options"] = ds.shards[0].grid_options
        if split == "train":
            info["train_coverage_mean"] = lock["splits"]["train"]["statistics"]["coverage"]["mean"]
        files = [sh.path for sh in ds.shards]

        worst = [0.0]

        def checked(files, parts):
            for path, (rows, diff) in zip(files, parts):
                if diff > CHECK_TOLERANCE:
                    raise InputError(f"{path}: the heatmaps made from its occupancies differ from the stored "
                                     f"ones by {diff:.3g}; the shards were not made by this heatmap definition, "
                                     "so a pack of them would train on other targets")
                worst[0] = max(worst[0], diff)
                yield rows

        with process_pool(workers) as pool:
            entry = write_split(out, split, size, n, GRIDS, checked(files, pool.map(_pack_shard, files)), progress)
        info["splits"][split] = {**entry, "max_heatmap_difference": worst[0],
                                 "shard_format": max(sh.version for sh in ds.shards)}
    tmp = out / (PACK_NAME + ".tmp")
    tmp.write_text(json.dumps(info, indent=1) + "\n")
    os.replace(tmp, out / PACK_NAME)
    return info


def write_split(out: Path, split: str, size: int, n: int, grids, parts, progress: bool = True) -> dict:
    """Write ``<split>.h5`` of a pack, atomically, from parts of packed rows; its entry in ``pack.json``.

    Parameters
    ----------
    out : Path
        The pack folder.
    split : str
    size : int
        Grid side S.
    n : int
        Samples in all.
    grids : sequence of str
        The datasets written (:data:`GRIDS`, and ``slab`` in a context pack).
    parts : iterable of dict
        Per part, its rows: grid name -> (k, S^3 / 8) uint8.
    progress : bool
    """
    from colonbench.progress import bar as progress_bar

    row = size ** 3 // 8
    final = out / f"{split}.h5"
    tmp = out / f"{split}.h5.tmp-{os.getpid()}"
    at = 0
    bar = progress_bar(total=n, desc=f"pack {split}", unit="sample", enabled=progress)
    try:
        with h5py.File(tmp, "w", track_order=True) as h5:
            h5.attrs["grid_size"] = size
            sets = {g: h5.create_dataset(g, (n, row), dtype=np.uint8, chunks=(1, row), compression="gzip",
                                         compression_opts=9) for g in grids}
            for rows in parts:
                k = len(rows[grids[0]])
                for g in grids:
                    sets[g][at:at + k] = rows[g]
                at += k
                bar.update(k)
        if at != n:
            raise InputError(f"{split}: {at} samples were packed where {n} were counted")
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    finally:
        bar.close()
    with open(tmp, "rb+") as fh:
        os.fsync(fh.fileno())
    os.replace(tmp, final)
    return {"samples": n, "file": final.name, "sha256": sha256_file(final), "bytes": final.stat().st_size}


class _Serial:
    def map(self, fn, items):
        return map(fn, items)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


def process_pool(workers: int):
    """A context manager with ``map(fn, items)``: this process for ``workers`` <= 1, else that many spawned processes."""
    if workers <= 1:
        return _Serial()
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor
    return ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"))


def _stored_bits(shard) -> dict:
    """A format-2 shard's stored grids, ``GRIDS`` -> (n, S^3 / 8) uint8; an :class:`InputError` naming the first
    sample with an empty grid (no heatmap can be made of it)."""
    bits = {g: shard.h5["samples"][g][()] for g in GRIDS}
    for g, rows in bits.items():
        empty = np.flatnonzero(~rows.any(axis=1))
        if len(empty):
            raise InputError(f"{shard.path}: sample {int(empty[0])} has an empty {g} grid; the dataset is damaged "
                             "(run colonbench verify)")
    return bits


def read_shard_bits(data_dir, split: str) -> tuple[dict, dict]:
    """One split of a format-2 dataset folder as a pack's split: its occupancy grids, read from the shards.

    Returns
    -------
    info : dict
        As a ``pack.json``: ``grid_options``, ``train_coverage_mean``, ``manifest_sha256``, ``manifest_name``.
    bits : dict
        ``s0``, ``s1``, ``c``: (n, S^3 / 8) uint8, the samples in the lock's shard order.
    """
    from colonbench.shards.reader import Shard, dataset_files

    data_dir = Path(data_dir)
    lock = dataset_lock(data_dir, [split])
    shards = [Shard(f) for f in dataset_files(data_dir, split)]
    old = [str(sh.path) for sh in shards if sh.version < 2]
    if old:
        raise InputError(f"{old[0]}: a format-1 shard (heatmaps stored, no occupancy grids); make a pack of "
                         f"{data_dir} (colonbench pack) or generate it again")
    parts = {g: [] for g in GRIDS}
    for sh in shards:
        with sh:
            bits = _stored_bits(sh)
            for g in GRIDS:
                parts[g].append(bits[g])
    info = {"grid_options": shards[0].grid_options, "manifest_sha256": lock["manifest_sha256"],
            "manifest_name": lock.get("manifest_name"),
            "train_coverage_mean": lock["splits"].get("train", {}).get("statistics", {}).get("coverage", {})
            .get("mean")}
    return info, {g: np.concatenate(p) for g, p in parts.items()}


def read_pack(pack_dir, split: str) -> tuple[dict, dict]:
    """Load one split of a pack into memory, checking it against ``pack.json``.

    Returns
    -------
    info : dict
        ``pack.json``.
    bits : dict
        ``s0``, ``s1``, ``c`` (and ``slab`` in a context pack): (n, S^3 / 8) uint8 packed occupancies.
    """
    pack = Path(pack_dir)
    if not is_pack(pack):
        raise InputError(f"{pack}: not a pack (no {PACK_NAME}); write one with colonbench pack")
    info = json.loads((pack / PACK_NAME).read_text())
    if info.get("format") != PACK_FORMAT or info.get("format_version") != PACK_VERSION:
        raise InputError(f"{pack}: pack format {info.get('format')} version {info.get('format_version')}; "
                         f"this colonbench reads {PACK_FORMAT} version {PACK_VERSION}")
    if split not in info["splits"]:
        raise InputError(f"{pack}: the pack has no {split} split (it has {', '.join(info['splits'])})")
    meta = info["splits"][split]
    path = pack / meta["file"]
    if not path.is_file():
        raise InputError(f"{path}: missing; the pack is incomplete")
    if sha256_file(path) != meta["sha256"]:
        raise InputError(f"{path}: its sha256 differs from the one in {PACK_NAME}; the file is damaged or "
                         "from another pack")
    with h5py.File(path, "r") as h5:
        bits = {g: h5[g][()] for g in GRIDS + ((SLAB,) if SLAB in h5 else ())}
    if any(len(b) != meta["samples"] for b in bits.values()):
        raise InputError(f"{path}: sample counts disagree with {PACK_NAME}")
    return info, bits
