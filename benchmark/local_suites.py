"""Suites built on the user's machine from data colonbench may not ship (``colonbench suites build``): their
registry is the suite cache itself.

A locally built suite lives in one folder under the suite data root (``$COLONBENCH_DATA``, else
``$XDG_CACHE_HOME/colonbench/suites``, else ``~/.cache/colonbench/suites``, or ``--data``), named by its id, and
holds beside its shards and lock:

``built-suite.json``
    its registry entry (:func:`entry`): id, name, importer and its version, the build's options, what it
    tests, its sample count, content hash and signature digest, and its source: the digest of every file of
    the download it read, per sequence what was checked and found;
``signature.json.gz``
    its per-sample signature (:mod:`colonbench.benchmark.signature`), made when it was built: evaluation
    checks the data against it as a shipped suite's data are checked against the published one, so a folder
    changed since it was built is refused.

Its id is ``<name>-<12 hex>``, the digest of the importer's name and version, the build's options and the
download's file digests: two users with the same download and options build the same id (and, on one machine,
the same bytes). It has no published signature (nobody else can check it without the download), so a paper
cites it by its id, the importer version and the download's own citation. :func:`lookup` finds one by id, or by
name where one suite of that name is built.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from colonbench.benchmark.suites import COLON_METRICS, SEGMENT_METRICS, Suite
from colonbench.errors import InputError

#: A locally built suite's registry entry and its signature, in its folder.
FILE = "built-suite.json"
#: Datasets whose suites are built from a user's download (``colonbench suites build NAME --from DIR``), named
#: ``<dataset>-<id>``.
DOWNLOADS = ("c3vd",)
SIGNATURE_FILE = "signature.json.gz"
FORMAT = "colonbench-local-suite"
FORMAT_VERSION = 1


@dataclass(frozen=True)
class LocalSuite(Suite):
    """A suite built on this machine (:mod:`colonbench.benchmark.local_suites`).

    Attributes
    ----------
    local_id : str
        Its id, ``<name>-<12 hex>`` (not ``<name>-v<version>``: ``version`` is its importer's).
    folder : str
        Its data folder.
    """

    local_id: str = ""
    folder: str = ""

    @property
    def id(self) -> str:
        return self.local_id

    def record(self, check) -> dict:
        """:meth:`Suite.record`, and what it was built from: ``local``, ``importer``, ``options`` and ``source``
        (per sequence of the download the count and digest of its files; every file's digest is in the suite's
        ``built-suite.json``)."""
        entry = read_entry(Path(self.folder))
        source = entry.get("source", {})
        return {**super().record(check), "local": True, "importer": entry.get("importer"),
                "options": entry.get("options"),
                "source": {"digest": source.get("digest"),
                           "sequences": {n: {k: s.get(k) for k in ("files", "sha256")}
                                         for n, s in source.get("sequences", {}).items()}}}


def read_entry(folder: Path) -> dict:
    """A local suite folder's ``built-suite.json`` ({} when there is none).

    Raises
    ------
    InputError
        It is there but unreadable.
    """
    path = Path(folder) / FILE
    if not path.is_file():
        return {}
    try:
        entry = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise InputError(f"{path}: unreadable ({exc}); build the suite again (colonbench suites build)") from None
    if not isinstance(entry, dict) or entry.get("format") != FORMAT:
        raise InputError(f"{path}: not a colonbench local suite entry")
    return entry


def load(folder) -> LocalSuite | None:
    """The local suite whose folder this is, or None (no ``built-suite.json``)."""
    entry = read_entry(Path(folder))
    if not entry:
        return None
    missing = [k for k in ("name", "version", "tests", "samples", "sha256", "noise_mm", "noise_seed", "signature", "id")
               if k not in entry]
    if missing:
        raise InputError(f"{Path(folder) / FILE}: not a built suite's record (no {', '.join(missing)}); build it again "
                         "(colonbench suites build)")
    task = entry.get("task", "segments")
    colon = {"contexts_mm": tuple(float(x) for x in entry.get("contexts_mm", ())),
             "segment_mm": float(entry.get("segment_mm", 60.0))} if task == "colon" else {}
    return LocalSuite(entry["name"], int(entry["version"]), "", task, entry["tests"],
                      int(entry["samples"]), entry["sha256"], float(entry.get("build_seconds", 0.0)),
                      noise_mm=tuple(float(x) for x in entry["noise_mm"]), noise_seed=int(entry["noise_seed"]),
                      metrics=COLON_METRICS if task == "colon" else SEGMENT_METRICS, signature=entry["signature"],
                      local_id=entry["id"], folder=str(Path(folder)), **colon)


def found(root=None) -> list[LocalSuite]:
    """The local suites under a data root (default: :func:`colonbench.benchmark.suites.default_data_root`), by id."""
    from colonbench.benchmark.suites import default_data_root

    root = Path(root) if root is not None else default_data_root()
    if not root.is_dir():
        return []
    out = []
    for path in sorted(root.glob(f"*/{FILE}")):
        if not path.parent.name.startswith("."):
            try:
                suite = load(path.parent)
            except InputError:
                continue
            if suite is not None and suite.id == path.parent.name:
                out.append(suite)
    return out


def lookup(name: str, root=None) -> LocalSuite | None:
    """A local suite by id, or by name where exactly one of that name is built; None where none is.

    Raises
    ------
    InputError
        Several suites of that name are built (the message lists their ids).
    """
    suites = found(root)
    for s in suites:
        if s.id == name:
            return s
    named = [s for s in suites if s.name == name]
    if len(named) > 1:
        raise InputError(f"{len(named)} {name} suites are built here ({', '.join(s.id for s in named)}): name one by "
                         "its id")
    return named[0] if named else None


def signature(suite: LocalSuite) -> dict:
    """A local suite's signature, made when it was built (checked against the digest its entry records).

    Raises
    ------
    InputError
        Missing, or not the one its entry names (the folder was changed).
    """
    import gzip

    from colonbench.benchmark.verification import digest

    path = Path(suite.folder) / SIGNATURE_FILE
    try:
        published = json.loads(gzip.decompress(path.read_bytes()))
    except (OSError, ValueError) as exc:
        raise InputError(f"{path}: unreadable ({exc}); build the suite again (colonbench suites build)") from None
    if digest(published) != suite.signature:
        raise InputError(f"{path}: its digest is {digest(published)}, {FILE} names {suite.signature}: the folder was "
                         "changed since it was built; build it again")
    return published


def publish(root, jobs) -> list[tuple[LocalSuite, bool]]:
    """Build suites into hidden folders beside their places and rename them into place only when every one is
    complete: on any error every hidden folder is removed, and nothing half-built remains.

    Parameters
    ----------
    root : path
        The suite data root.
    jobs : list of (str, callable)
        Each suite's id and its maker: ``make(folder) -> entry`` writes the suite's data into ``folder`` and
        returns its registry entry (written here as :data:`FILE`, last), or None where there is no such suite.

    Returns
    -------
    list of (LocalSuite, bool) or None
        Per job, the suite and whether it was built (False: it was already built, nothing was done); None where
        its maker returned None.

    Raises
    ------
    InputError
        A suite's place holds something that is not a built suite; whatever a maker raises.
    """
    import os
    import shutil

    root = Path(root)
    out, staged = [None] * len(jobs), []
    try:
        for k, (sid, make) in enumerate(jobs):
            target = root / sid
            if (target / FILE).is_file():
                out[k] = (load(target), False)
                continue
            if target.exists():
                raise InputError(f"{target}: exists and is not a built suite; remove it and build again")
            root.mkdir(parents=True, exist_ok=True)
            tmp = root / f".{sid}.tmp-{os.getpid()}"
            shutil.rmtree(tmp, ignore_errors=True)
            tmp.mkdir()
            staged.append((k, tmp, target))
            entry = make(tmp)
            if entry is None:                  # nothing of the download makes this suite
                shutil.rmtree(tmp, ignore_errors=True)
                staged.pop()
                continue
            (tmp / FILE).write_text(json.dumps(entry, indent=1) + "\n")
        for k, tmp, target in staged:
            try:
                os.replace(tmp, target)
            except OSError:                    # another build of the same download finished first: keep its suite
                if load(target) is None:
                    raise InputError(f"{target}: cannot put the built suite in place (a folder is there that is "
                                     "not a built suite; remove it)") from None
                shutil.rmtree(tmp, ignore_errors=True)
            out[k] = (load(target), True)
    except BaseException:
        for _, tmp, _ in staged:
            shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out
