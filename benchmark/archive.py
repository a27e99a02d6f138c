"""Frozen suite archives: one file with exactly what a suite scores, and fetching one into the suite cache.

An archive is an uncompressed POSIX tar (its shards are compressed inside)
holding a dataset folder in the shard format, restricted to what the suite
scores::

    suite.json            what it is: format, suite id, signature digest, content hash, bit-identical or not
    dataset.lock.json     the folder's lock (manifest and config hashes, the shards, their sha256)
    test/<shard>.h5       the suite's shards; where a shard has samples the suite does not score, a subset
                          (colonbench.shards.subset): the other rows empty, every sample keeping its index

so that a fetched archive is read exactly as a generated suite: the inputs as
generated (noise is added at evaluation by the suite's own draw, bit for bit
as for generated data), the truth, every sample under its id. The tar is
written in a fixed order with no owners or times, so the same data give the
same bytes; its sha256 is what a fetch checks first.
"""

from __future__ import annotations

import io
import json
import logging
import os
import re
import shutil
import tarfile
from pathlib import Path

from colonbench.errors import InputError

logger = logging.getLogger(__name__)

FORMAT = "colonbench-suite-archive"
FORMAT_VERSION = 1
#: The description file at the top of an archive.
INFO_NAME = "suite.json"


def _add(tar: tarfile.TarFile, name: str, data: bytes) -> None:
    info = tarfile.TarInfo(name)
    info.size, info.mtime, info.mode, info.uid, info.gid = len(data), 0, 0o644, 0, 0
    tar.addfile(info, io.BytesIO(data))


def write_archive(suite, data, out, progress: bool = True) -> dict:
    """Write the archive of a suite's data folder.

    The data must hold the suite (verified against its published signature); the archive records whether it is
    bit-identical to the published data.

    Parameters
    ----------
    suite : Suite
    data : path
        The suite's data folder.
    out : path
        The archive file to write (replaced).

    Returns
    -------
    dict
        ``suite.json``'s content plus ``sha256`` of the archive file and ``bytes``.
    """
    from colonbench.benchmark import suites
    from colonbench.benchmark.evaluate import read_lock, select
    from colonbench.shards.schema import sha256_file
    from colonbench.shards.subset import write_subset

    data = Path(data)
    result = suites.check(suite, data)
    if not result.verified:
        raise InputError(f"{data} does not hold suite {suite.id}: {result.first_difference()}; an archive is made of "
                         "a verified suite only")
    _, picks = select(data, suite.split, suite.limit)
    lock = read_lock(data)
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    staging = out.with_name(f".{out.name}.parts-{os.getpid()}")
    tmp = out.with_name(f".{out.name}.tmp-{os.getpid()}")
    shutil.rmtree(staging, ignore_errors=True)
    try:
        shards, subsets = {}, {}
        for name, indices in picks:
            entry = dict(lock["shards"][name])
            if len(indices) == int(entry["samples"]):
                path = data / name
            else:
                path = write_subset(data / name, staging / name, indices)
                subsets[name] = [int(i) for i in indices]
            entry.update(sha256=sha256_file(path), bytes=path.stat().st_size)
            shards[name] = (path, entry)
        new_lock = {k: v for k, v in lock.items() if k not in ("shards", "missing", "splits")}
        new_lock.update(splits={suite.split: lock["splits"][suite.split]}, missing=[],
                        shards={n: e for n, (_, e) in shards.items()})
        if subsets:   # the rows the subset shards hold (colonbench.benchmark.evaluate.select reads only those)
            new_lock["kept_samples"] = subsets
        info = {"format": FORMAT, "format_version": FORMAT_VERSION, "suite": suite.id, "signature": suite.signature,
                "sha256": result.sha256, "bit_identical": bool(result.bit_identical),
                "samples": len(result.samples)}
        with tarfile.open(tmp, "w", format=tarfile.PAX_FORMAT) as tar:
            _add(tar, INFO_NAME, json.dumps(info, indent=1).encode())
            _add(tar, "dataset.lock.json", json.dumps(new_lock, indent=1, sort_keys=True).encode())
            for name in sorted(shards):
                _add(tar, name, shards[name][0].read_bytes())
        os.replace(tmp, out)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
        tmp.unlink(missing_ok=True)
    return {**info, "sha256_archive": sha256_file(out), "bytes": out.stat().st_size}


def _check_members(tar: tarfile.TarFile) -> None:
    for m in tar.getmembers():
        parts = Path(m.name).parts
        if not m.isfile() or m.name.startswith("/") or ".." in parts:
            raise InputError(f"not a colonbench suite archive: it holds {m.name!r}")


def fetch(suite, url: str, sha256: str, root=None, progress: bool = True) -> Path:
    """Download a suite's archive into the suite cache, checked, from where every command uses it.

    The download (pooch: checked by sha256, with a progress bar) must have ``sha256``; the archive must hold
    ``suite`` and its data must verify against the suite's published signature. Only then is it put in place as
    the suite's folder under ``root``, which must not exist yet; on any failure nothing is left in the cache.

    Parameters
    ----------
    suite : Suite
    url : str
        http(s), ftp or doi address of the archive (pooch's downloaders).
    sha256 : str
        Its sha256, 64 hex digits.
    root : path, optional
        The suite cache (default :func:`colonbench.benchmark.suites.default_data_root`).

    Returns
    -------
    Path
        The suite's data folder.
    """
    import pooch

    from colonbench.benchmark import suites

    if not progress:
        pooch.get_logger().setLevel("WARNING")   # no "Downloading data from ..." line either

    sha256 = str(sha256).strip().lower()
    if not re.fullmatch(r"[0-9a-f]{64}", sha256):
        raise InputError(f"--sha256 must be the archive's sha256, 64 hex digits; got {sha256!r}")
    target = suites.data_dir(suite, root)
    if target.exists():
        raise InputError(f"{target} exists: the suite's data are cached there already (colonbench suites --check says "
                         "whether they verify); remove the folder to fetch the archive in its place")
    target.parent.mkdir(parents=True, exist_ok=True)
    staging = target.parent / f".fetch-{suite.id}-{os.getpid()}"
    shutil.rmtree(staging, ignore_errors=True)
    staging.mkdir()
    try:
        try:
            path = pooch.retrieve(url, known_hash=f"sha256:{sha256}", fname="archive.tar", path=staging,
                                  progressbar=_download_bar(url, progress))
        except ValueError as exc:           # pooch: the download's hash is not the known one
            raise InputError(f"{url}: refused, {_hash_words(exc)}") from None
        except Exception as exc:  # noqa: BLE001 - any transport failure is the user's to see, in one line
            raise InputError(f"{url}: the download failed ({type(exc).__name__}: {exc})") from None
        folder = staging / "data"
        try:
            with tarfile.open(path) as tar:
                _check_members(tar)
                tar.extractall(folder, **({"filter": "data"} if hasattr(tarfile, "data_filter") else {}))
        except tarfile.TarError as exc:
            raise InputError(f"{url}: not a readable suite archive ({exc})") from None
        try:
            info = json.loads((folder / INFO_NAME).read_text())
        except (OSError, ValueError):
            raise InputError(f"{url}: not a colonbench suite archive (no {INFO_NAME})") from None
        if info.get("format") != FORMAT or info.get("suite") != suite.id:
            raise InputError(f"{url}: an archive of {info.get('suite')!r} ({info.get('format')}), not of {suite.id}")
        logger.info("%s: downloaded; checking its data against %s", suite.id, suite.signature)
        result = suites.check(suite, folder)
        if not result.verified:
            raise InputError(f"{url}: its data do not verify against {suite.signature}: {result.first_difference()}")
        folder.rename(target)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return target


class _PoochBar:
    """pooch's progress bar interface over :func:`colonbench.progress.bar`, one bar that only goes forwards.

    pooch counts whole chunks (past the size on the last one), then calls ``reset()`` and ``update(total)`` to
    show the bar full: on its own tqdm bar that jumps back to 0 % before 100 %. Here ``reset`` does nothing and the
    count stops at the total.
    """

    def __init__(self, enabled: bool):
        self.enabled = enabled
        self._bar = None

    @property
    def total(self):
        return None if self._bar is None else self._bar.total

    @total.setter
    def total(self, value):   # pooch sets it once it knows the size (0: no Content-Length)
        from colonbench.progress import bar

        self._bar = bar(total=int(value) or None, desc="download", unit="B", enabled=self.enabled)

    def update(self, n):
        if self._bar is None:
            self.total = 0
        self._bar.update(n)

    def reset(self):
        pass

    def close(self):
        if self._bar is not None:
            self._bar.close()


def _download_bar(url: str, progress: bool):
    """pooch's ``progressbar``: one forward-only bar (http(s), doi); pooch's own tqdm for ftp and sftp, which take
    no other, only on a terminal."""
    from colonbench.progress import on_terminal

    if str(url).lower().startswith(("ftp:", "sftp:")):
        return bool(progress and on_terminal())
    return _PoochBar(progress) if progress else False


def _hash_words(exc: Exception) -> str:
    """pooch's hash mismatch in one sentence."""
    text = " ".join(str(exc).split())
    m = re.search(r"expected (?:sha256:)?([0-9a-f]+) but got ([0-9a-f]+)", text)
    if m:
        return f"its sha256 is {m.group(2)}, not {m.group(1)} (a wrong --sha256, or a truncated or changed file)"
    return text
