"""``colonbench verify``: is a dataset folder (or one shard) complete, intact and of the schema?"""

from __future__ import annotations

import json
from pathlib import Path

import h5py

from colonbench.shards import schema
from colonbench.shards.dataset import LOCK_FORMAT, LOCK_NAME
from colonbench.shards.schema import sha256_file
from colonbench.shards.writer import TMP_SUFFIX


def check_shard(path) -> list[str]:
    """Schema faults of one shard file (empty when it conforms); an unreadable file is a fault too."""
    try:
        with h5py.File(path, "r") as h5:
            return schema.check(h5)
    except OSError as exc:
        return [f"not a readable HDF5 file ({exc})"]


def verify(path, deep: bool = True) -> list[str]:
    """Every fault of a dataset folder or shard file, each naming the file; empty when all is well.

    A folder is checked against its ``dataset.lock.json``: every shard it
    lists must exist with the recorded size and sha256 and conform to the
    schema with the recorded sample count; files that look like shards but are
    not in the lock, and leftovers of killed runs, are reported too.

    Parameters
    ----------
    path : path
        Dataset folder or ``.h5`` shard.
    deep : bool
        Also run the schema check on every shard (reads all heatmaps).
    """
    path = Path(path)
    if path.is_file():
        return [f"{path}: {f}" for f in check_shard(path)]
    if not path.is_dir():
        return [f"{path}: no such dataset folder or shard file"]
    lock_path = path / LOCK_NAME
    if not lock_path.exists():
        return [f"{lock_path}: missing (not a generated dataset, or generation did not finish; rerun generate)"]
    try:
        lock = json.loads(lock_path.read_text())
    except json.JSONDecodeError as exc:
        return [f"{lock_path}: not valid JSON ({exc})"]
    if not isinstance(lock, dict) or lock.get("format") != LOCK_FORMAT or not isinstance(lock.get("shards"), dict):
        return [f"{lock_path}: not a colonbench dataset lock"]
    faults = []
    for name, entry in lock["shards"].items():
        f = path / name
        if not f.exists():
            faults.append(f"{f}: missing (listed in the lock)")
            continue
        if f.stat().st_size != entry.get("bytes"):
            faults.append(f"{f}: {f.stat().st_size} bytes, the lock says {entry.get('bytes')}")
            continue
        if sha256_file(f) != entry.get("sha256"):
            faults.append(f"{f}: sha256 differs from the lock (the file was changed or corrupted)")
            continue
        problems = check_shard(f) if deep else []
        if not problems:
            with h5py.File(f, "r") as h5:
                if int(h5.attrs["n_samples"]) != entry.get("samples"):
                    problems.append(f"{int(h5.attrs['n_samples'])} samples, the lock says {entry.get('samples')}")
                if h5.attrs["manifest_sha256"] != lock.get("manifest_sha256"):
                    problems.append("belongs to another manifest than the lock")
        faults += [f"{f}: {p}" for p in problems]
    listed = set(lock["shards"])
    for f in sorted(path.rglob("*.h5")):
        rel = f.relative_to(path).as_posix()
        if rel not in listed:
            faults.append(f"{f}: a shard file not listed in the lock")
    for f in sorted(path.rglob(f"*.h5{TMP_SUFFIX}*")):
        faults.append(f"{f}: leftover of an interrupted generation (rerun generate to finish and remove it)")
    return faults
