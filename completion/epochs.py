"""Which samples each training epoch draws, from one or several datasets (their repeats and shares), and the
identity of the datasets a run trains on (their locks), recorded in the run and its model."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np

from colonbench import seeding
from colonbench.errors import InputError
from colonbench.shards.schema import LOCK_NAME


def epoch_order(n: int, seed: int, epoch: int) -> np.ndarray:
    """The sample order of an epoch: a permutation drawn from stream ``("shuffle", epoch)``."""
    return seeding.rng(seed, "shuffle", epoch).permutation(n)


def per_dataset(repeat, n: int) -> list[int]:
    """``repeat`` as one count per dataset of ``n`` (all 1 when empty), or an :class:`InputError`."""
    repeat = list(repeat) or [1] * n
    if len(repeat) != n:
        raise InputError(f"--repeat gives {len(repeat)} number(s) for {n} dataset(s); give one per dataset")
    return repeat


def epoch_slots(sizes, repeat=()) -> np.ndarray:
    """(m,) int: the training sample behind each slot of an epoch, each dataset's samples ``repeat`` times.

    Several datasets train as one set, in the order given, ``sizes`` samples
    each; dataset ``i`` fills ``repeat[i]`` slots per sample (all 1 when
    ``repeat`` is empty), so a small source (two real colons beside 150
    procedural ones) weighs more without being copied. An epoch visits the
    slots in the order :func:`epoch_order` draws; flips and erasures are
    drawn per slot, so a repeated sample is augmented differently each time.
    With every repeat 1, slot ``k`` is sample ``k``.
    """
    sizes = [int(n) for n in sizes]
    repeat = per_dataset(repeat, len(sizes))
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
    return np.concatenate([np.tile(np.arange(a, a + n), r) for a, n, r in zip(starts, sizes, repeat)])


def _data_lock(data_dir: Path) -> dict:
    """What the run needs to know of its data: ``manifest_sha256``, ``train_coverage_mean``, ``pack``,
    ``occupancies`` (a pack, or shards of format 2: the occupancy grids can be read without the geometry),
    ``train_samples``, ``samples`` (train and validation) and ``grid_mib`` (their grids held bit-packed)."""
    from colonbench.shards.pack import GRIDS, PACK_NAME, is_pack
    from colonbench.shards.reader import dataset_files, read_attrs
    pack = is_pack(data_dir)
    lock = data_dir / (PACK_NAME if pack else LOCK_NAME)
    if not lock.exists():
        raise InputError(f"{data_dir}: neither {LOCK_NAME} nor {PACK_NAME}; generate the dataset first "
                         "(colonbench generate)")
    lock = json.loads(lock.read_text())
    missing = [s for s in ("train", "validation") if s not in lock.get("splits", {})]
    if missing:
        raise InputError(f"{data_dir}: the {'pack' if pack else 'dataset'} has no {' and no '.join(missing)} split; "
                         "make it with them")
    coverage = lock["train_coverage_mean"] if pack else lock["splits"]["train"]["statistics"]["coverage"]["mean"]
    samples = lock["splits"]["train"].get("samples")
    both = sum(lock["splits"][s].get("samples") or 0 for s in ("train", "validation"))
    occupancies = pack or int(lock.get("shard_format_version", 1)) >= 2
    size = int(lock["grid_options"]["size"] if pack else read_attrs(dataset_files(data_dir, "train")[0])["grid_size"])
    return {"manifest_sha256": lock["manifest_sha256"], "train_coverage_mean": coverage, "pack": pack,
            "occupancies": occupancies, "train_samples": samples, "samples": both,
            "grid_mib": both * len(GRIDS) * size ** 3 / 8 / 2 ** 20}


def data_locks(data_dirs: list[Path], repeat=()) -> dict:
    """:func:`_data_lock` of one or more dataset folders trained on together.

    Several folders must all be shard datasets or all packs, with the same grid; their
    ``manifest_sha256`` is then the SHA-256 of theirs joined by ``+`` (in the
    order given), ``manifests`` lists theirs, and ``train_coverage_mean`` is
    the mean over all their training samples (each counted ``repeat`` times).
    """
    locks = [_data_lock(d) for d in data_dirs]
    if len(locks) == 1:
        return {**locks[0], "manifests": [locks[0]["manifest_sha256"]]}
    if len({lk["pack"] for lk in locks}) > 1:
        raise InputError("datasets trained together must be all shard folders or all packs, not both; "
                         "pack the others too (colonbench pack) or train on every dataset's shards")
    n = [lk["train_samples"] or 1 for lk in locks]
    weights = [k * r for k, r in zip(n, per_dataset(repeat, len(locks)))]
    hashes = [lk["manifest_sha256"] for lk in locks]
    return {"manifest_sha256": hashlib.sha256("+".join(hashes).encode()).hexdigest(), "manifests": hashes,
            "train_coverage_mean": float(np.average([lk["train_coverage_mean"] for lk in locks], weights=weights)),
            "pack": locks[0]["pack"], "occupancies": all(lk["occupancies"] for lk in locks), "train_samples": sum(n),
            "samples": sum(lk["samples"] for lk in locks), "grid_mib": sum(lk["grid_mib"] for lk in locks)}
