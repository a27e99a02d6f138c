"""Generating a dataset from a manifest: shards in parallel, resumable, and the lock that describes them.

A dataset folder holds::

    manifest.yaml          the resolved manifest (every default written out)
    train/colon-00000-50mm.h5, ...   the shards (colonbench.shards.schema)
    dataset.lock.json      per-shard sha256, bytes and counts; per-split statistics
    stats.png              holes per sample, hole sizes and coverage per split (the paper's Fig. 2b)

:func:`generate` makes only the shards that are missing, so a second run after
an interruption finishes the job, and a run with more splits extends it. Shard
bytes do not depend on the executor: one process, ``workers`` processes or a
Dask cluster give the same files.
"""

from __future__ import annotations

import functools
import json
import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

import h5py
import numpy as np
import yaml

from colonbench._version import __version__
from colonbench.errors import ColonbenchError, InputError
from colonbench.folderlock import folder_lock
from colonbench.shards import schema, stats
from colonbench.shards.build import build_shard
from colonbench.shards.manifest import SPLITS, config_hash, dumps, load, manifest_hash, resolve, task, units
from colonbench.shards.schema import LOCK_NAME, sha256_file
from colonbench.shards.writer import TMP_SUFFIX

MANIFEST_NAME = "manifest.yaml"
STATS_NAME = "stats.png"
LOCK_FORMAT = "colonbench-dataset-lock"
LOCK_VERSION = 1


def _job(resolved: dict, out_dir: str, unit):
    """Build one shard and hash it; failures come back as values so one bad shard does not stop the others."""
    try:
        info = build_shard(resolved, unit, out_dir)
    except ColonbenchError as exc:
        return {"name": unit.name, "error": str(exc)}
    except Exception as exc:  # noqa: BLE001 - reported with the shard's name, the run goes on
        return {"name": unit.name, "error": f"{type(exc).__name__}: {exc}"}
    path = Path(out_dir) / unit.name
    info.update(sha256=sha256_file(path), bytes=path.stat().st_size)
    return info


def _each(fn, jobs) -> list:
    """``fn`` of each job, in order, in one process."""
    return [fn(j) for j in jobs]


def _execute(fn, jobs, workers: int, scheduler):
    """Run ``fn`` over ``jobs``; yields results as they complete."""
    if scheduler is not None:
        try:
            from distributed import Client, as_completed as dask_completed
        except ImportError as exc:
            raise InputError("--scheduler needs Dask: pip install 'colonbench[cluster]' "
                             f"(import failed: {exc})") from None
        client = Client(scheduler) if isinstance(scheduler, str) else scheduler
        try:
            futures = client.map(fn, jobs, pure=False)
            for fut in dask_completed(futures):
                yield fut.result()
        finally:
            if isinstance(scheduler, str):
                client.close()
    elif workers > 1 and len(jobs) > 1:
        # a colon's shards go to one process, in order, so that it makes the colon once (build keeps it)
        groups = {}
        for j in jobs:
            groups.setdefault(getattr(j, "colon_key", id(j)), []).append(j)
        if len(groups) < workers:  # fewer colons than workers: a shard a task, the colon made in each
            groups = {k: [j] for k, j in enumerate(jobs)}
        ctx = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(max_workers=min(workers, len(groups)), mp_context=ctx) as pool:
            futures = [pool.submit(_each, fn, g) for g in sorted(groups.values(), key=len, reverse=True)]
            for fut in as_completed(futures):
                yield from fut.result()
    else:
        for j in jobs:
            yield fn(j)


def _shard_ok(path: Path, digest: str) -> bool:
    """Whether an existing file under a shard's name is a finished shard of this manifest."""
    try:
        with h5py.File(path, "r") as h5:
            current = {schema.FORMAT: schema.FORMAT_VERSION, schema.COLON_FORMAT: schema.COLON_FORMAT_VERSION}
            fmt = h5.attrs.get("format")
            # a shard of an older format (an interrupted run of an older colonbench) is made again: one format a folder
            return (fmt in current and int(h5.attrs.get("format_version", -1)) == current[fmt]
                    and h5.attrs.get("manifest_sha256") == digest
                    and "n_samples" in h5.attrs)
    except OSError:
        return False


def _progress(total: int, initial: int, enabled: bool):
    from colonbench.progress import bar
    return bar(total=total, initial=initial, unit="shard", desc="generate", enabled=enabled)


def generate(manifest, out_dir, workers: int = 1, scheduler=None, splits=None, progress: bool = True,
             allow_version_mismatch: bool = False) -> dict:
    """Generate (or finish generating) the shards of a manifest, then write the lock and statistics.

    Parameters
    ----------
    manifest : path or dict
        A manifest YAML file, or a manifest dict (its mesh paths then relative
        to the current folder).
    out_dir : path
        Dataset folder; created if needed. It may already hold part of this
        same dataset, never another one.
    workers : int
        Local processes.
    scheduler : str or distributed.Client, optional
        A Dask scheduler address (``tcp://host:8786``) or client; shards are
        then made on its workers, which must see ``out_dir`` at the same path.
    splits : iterable of str, optional
        Only these splits (default: all of the manifest).
    progress : bool
        Show a progress bar on a terminal.
    allow_version_mismatch : bool
        Generate even if the manifest was written for another colonbench version.

    Returns
    -------
    dict
        The lock (also written to ``out_dir/dataset.lock.json``).
    """
    resolved = load(manifest) if not isinstance(manifest, dict) else resolve(manifest)
    base = Path(manifest).parent if not isinstance(manifest, dict) else Path.cwd()  # mesh paths are relative to it
    if resolved["generator_version"] != __version__ and not allow_version_mismatch:
        raise InputError(f"manifest {resolved['name']!r} was written for colonbench {resolved['generator_version']}, "
                         f"this is {__version__}: the data would differ. Install that version, or pass "
                         "--allow-version-mismatch to generate with this one (the lock records the version used)")
    if splits is not None:
        splits = list(splits)
        bad = [s for s in splits if s not in resolved["splits"]]
        if bad:
            raise InputError(f"split(s) {bad} are not in manifest {resolved['name']!r} "
                             f"(it has {list(resolved['splits'])})")
    if workers < 1:
        raise InputError(f"--workers must be >= 1, got {workers}")
    digest = manifest_hash(resolved)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    with folder_lock(out, "generate", "generation"):
        return _generate_locked(resolved, digest, out, workers, scheduler, splits, progress, base)


def _generate_locked(resolved, digest, out: Path, workers, scheduler, splits, progress, base) -> dict:
    saved = out / MANIFEST_NAME
    if saved.exists():
        try:
            previous = manifest_hash(resolve(yaml.safe_load(saved.read_text()), str(saved)))
        except (InputError, yaml.YAMLError):
            previous = None
        if previous != digest:
            raise InputError(f"{out} holds another dataset (its {MANIFEST_NAME} differs from manifest "
                             f"{resolved['name']!r}); generate into an empty folder")
    else:
        saved.write_text(dumps(resolved))
    saved_lock = _saved_lock(out)  # {} when none, or damaged (written anew when the run ends)
    if saved_lock:
        wrote = saved_lock.get("shard_format_version", 1)
        writes = schema.COLON_FORMAT_VERSION if task(resolved) == "colon" else schema.FORMAT_VERSION
        if wrote != writes:
            raise InputError(f"{out} holds shards of format {wrote}; this colonbench writes format {writes}, and a "
                             "dataset is one format. Generate into a new folder (the old one stays readable: "
                             "colonbench verify, evaluate and train read both)")
    for tmp in out.rglob(f"*.h5{TMP_SUFFIX}*"):
        tmp.unlink()  # left by a killed run; never a finished shard

    todo_all = units(resolved, splits, base)
    todo = [u for u in todo_all if not ((out / u.name).exists() and _shard_ok(out / u.name, digest))]
    hashes = _locked_shards(out)  # finished shards keep the hash of the last lock; write_lock hashes the others
    failures = []
    bar = _progress(len(todo_all), len(todo_all) - len(todo), progress)
    try:
        fn = functools.partial(_job, resolved, str(out))
        for info in _execute(fn, todo, workers, scheduler):
            if "error" in info:
                failures.append(f"{info['name']}: {info['error']}")
            else:
                hashes[info["name"]] = {"sha256": info["sha256"], "bytes": info["bytes"]}
            bar.update(1)
    finally:
        bar.close()
    if failures:
        raise ColonbenchError(f"{len(failures)} shard(s) failed; the others are kept and a rerun makes only the "
                              "missing ones:\n  " + "\n  ".join(failures))
    return write_lock(resolved, out, hashes)


def dataset_manifest(data_dir) -> dict:
    """The manifest a generated dataset folder was made from (its saved ``manifest.yaml``, as resolved).

    Raises
    ------
    InputError
        Not a generated dataset folder, or its manifest is not a readable YAML mapping.
    """
    path = Path(data_dir) / MANIFEST_NAME
    if not path.is_file():
        raise InputError(f"{data_dir}: not a dataset folder (no {MANIFEST_NAME}); generate the dataset first "
                         "(colonbench generate)")
    try:
        manifest = yaml.safe_load(path.read_text()) or {}
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: unreadable ({exc})") from None
    if not isinstance(manifest, dict):
        raise InputError(f"{path}: unreadable (not a mapping)")
    return manifest


def _saved_lock(out: Path) -> dict:
    """The lock in ``out`` ({} when there is none or it is unreadable)."""
    try:
        lock = json.loads((out / LOCK_NAME).read_text())
    except (OSError, json.JSONDecodeError):
        return {}
    return lock if isinstance(lock, dict) else {}


def _locked_shards(out: Path) -> dict:
    """The ``shards`` entries of the lock in ``out`` ({} when there is none or it is unreadable)."""
    shards = _saved_lock(out).get("shards", {})
    return shards if isinstance(shards, dict) else {}


def write_lock(resolved: dict, out: Path, hashes: dict | None = None) -> dict:
    """Describe every shard of the manifest present in ``out``: hashes, counts and per-split statistics.

    ``hashes`` maps shard names to known ``{"sha256", "bytes"}`` (default: the
    current lock's); a shard whose size differs from its known entry, or that
    has none, is hashed here.
    """
    digest = manifest_hash(resolved)
    whole = task(resolved) == "colon"
    previous = _locked_shards(out) if hashes is None else hashes
    shards, missing, per_split = {}, [], {}
    for u in units(resolved):
        path = out / u.name
        if not path.exists():
            missing.append(u.name)
            continue
        size = path.stat().st_size
        old = previous.get(u.name, {})
        sha = old["sha256"] if old.get("bytes") == size and "sha256" in old else sha256_file(path)
        with h5py.File(path, "r") as h5:
            n, m = int(h5.attrs["n_samples"]), int(h5.attrs.get("n_segments", 0))
            values = h5["samples/coverage"][()] if whole else None
        shards[u.name] = {"sha256": sha, "bytes": size, "samples": n, "segments": m, "split": u.split,
                          "colon_id": u.colon_id, "length_mm": u.length_mm}
        per_split.setdefault(u.split, []).append(values if whole else stats.shard_values(path))
    split_info = {}
    for split in SPLITS:
        if split not in per_split:
            continue
        entries = [s for s in shards.values() if s["split"] == split]
        split_info[split] = {"shards": len(entries), "samples": sum(s["samples"] for s in entries),
                             "segments": sum(s["segments"] for s in entries),
                             "colons": len({s["colon_id"] for s in entries}),
                             "bytes": sum(s["bytes"] for s in entries),
                             "statistics": {"coverage": stats.quantiles(np.concatenate(per_split[split]))}
                             if whole else stats.summarize(per_split[split])}
    lock = {"format": LOCK_FORMAT, "format_version": LOCK_VERSION, "manifest_name": resolved["name"],
            "manifest_sha256": digest, "config_sha256": config_hash(resolved),
            "generator_version": __version__,
            "shard_format_version": schema.COLON_FORMAT_VERSION if whole else schema.FORMAT_VERSION,
            "splits": split_info, "missing": missing, "shards": shards}
    tmp = out / (LOCK_NAME + ".tmp")
    tmp.write_text(json.dumps(lock, indent=1) + "\n")
    os.replace(tmp, out / LOCK_NAME)
    if split_info and not whole:
        stats.plot({k: v["statistics"] for k, v in split_info.items()}, out / STATS_NAME)
    return lock
