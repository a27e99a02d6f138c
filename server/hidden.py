"""Hidden suites: inputs published, truth kept where only the evaluation server reads it.

A hidden suite is a segment suite whose truth only the server holds. :func:`build` generates one from a segment
manifest (a named suite's, or any segment manifest file, procedural or naming real meshes: a user's private
colon meshes, each checked against the sha256 the manifest records and never copied) with its root seed replaced
by a **secret seed**; :func:`build_c3vd` builds one from a private C3VD download through the C3VD importer
(:mod:`colonbench.benchmark.c3vd_suite`), whose truth cannot be made without the download. It is a suite built
on this machine
(:mod:`colonbench.benchmark.local_suites`): its folder under a private data root holds the shards (inputs and
truth), the manifest with the secret seed, the lock, the per-sample signature and ``built-suite.json`` (marked
``"hidden": true``); ``colonbench score`` and the server's worker score it as any built suite.

What is published is what ``colonbench export`` writes (one PLY per evaluated cloud, noise added, ``index.csv``)
with a ``suite.json`` cut down to the suite's id, name, sample count and noise levels, and
:data:`INPUTS_FILE`, the digest of every published file. Neither the secret seed, nor the noise seed, nor the
signature (which holds each sample's true coverage) is written there, so the published inputs are enough to run a
method and not enough to regenerate the truth.

The suite's id is ``<name>-<12 hex>``, a digest of the seed and of the manifest without it: rebuilding with the
same seed and manifest gives the same id. Seeds are drawn from ``secrets`` (or given, at least 2**40 and below
2**63) so that neither the id nor the inputs can be searched back to the seed.
"""

from __future__ import annotations

import json
import os
import secrets
import shutil
import time
from pathlib import Path

from colonbench.benchmark.c3vd_suite import json_digest
from colonbench.errors import InputError
from colonbench.shards.manifest import meshes_section
from colonbench.shards.schema import sha256_file

#: Seeds below this are refused: anyone could regenerate the suite with every smaller seed and compare inputs.
MIN_SEED = 2 ** 40
#: Seeds are stored as 64-bit signed integers in places (HDF5 attributes): below this.
MAX_SEED = 2 ** 63
#: The file of a published hidden suite's folder naming every published file's sha256 and their digest.
INPUTS_FILE = "inputs.sha256.json"
IMPORTER = "hidden"
IMPORTER_VERSION = 1
NOISE_MM = (0.0, 0.5)
#: The files a manifest's mesh entry names (each with its ``<key>_sha256``).
MESH_FILES = ("mesh", "centerline")


def new_seed() -> int:
    """A secret seed drawn from the operating system's randomness, in [:data:`MIN_SEED`, :data:`MAX_SEED`)."""
    return MIN_SEED + secrets.randbelow(MAX_SEED - MIN_SEED)


def read_seed(path) -> int:
    """A secret seed from a file holding one integer.

    Raises
    ------
    InputError
        Unreadable, not one integer, or outside [:data:`MIN_SEED`, :data:`MAX_SEED`).
    """
    path = Path(path)
    try:
        text = path.read_text().strip()
    except OSError as exc:
        raise InputError(f"{path}: cannot read the secret seed ({exc.strerror})") from None
    try:
        seed = int(text)
    except ValueError:
        raise InputError(f"{path}: the secret seed file must hold one integer") from None
    if not MIN_SEED <= seed < MAX_SEED:
        raise InputError(f"{path}: a secret seed must be at least 2**40 and below 2**63 (a smaller one can be found "
                         "by regenerating with every seed below it); leave --seed-file out to draw one")
    return seed


def _manifest(source) -> tuple[dict, str]:
    """The manifest of ``source`` (a named suite or a manifest file) as a dict, and what to call it."""
    import yaml

    from colonbench.benchmark import suites

    path = Path(source)
    if not path.is_file():
        try:
            suite = suites.get(str(source))
        except InputError:
            raise InputError(f"{source}: neither a manifest file nor a named suite (colonbench suites)") from None
        if suite.task != "segments":
            raise InputError(f"{suite.id} is a whole-colon suite: hidden suites are built from segment manifests")
        path = suites.manifest_path(suite)
    try:
        raw = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise InputError(f"{path}: not a readable manifest ({exc})") from None
    if not isinstance(raw, dict) or "splits" not in raw:
        raise InputError(f"{path}: not a colonbench dataset manifest")
    if raw.get("task", "segments") != "segments":
        raise InputError(f"{path}: a {raw.get('task')} manifest; hidden suites are built from segment manifests")
    if "test" not in raw["splits"]:
        raise InputError(f"{path}: has no test split, which a hidden suite is made of")
    if raw.get("meshes"):
        raw = {**raw, "meshes": _meshes_at(raw["meshes"], path)}
    return raw, str(raw.get("name", path.stem))


def _meshes_at(meshes, manifest) -> dict:
    """A manifest's ``meshes``, checked as every manifest's are
    (:func:`colonbench.shards.manifest.meshes_section`), with each mesh and centerline path made absolute (they are
    relative to the manifest's folder, and the manifest is copied into the private folder), each file checked
    against the sha256 the manifest records.

    Raises
    ------
    InputError
        A malformed entry, a file missing, or one whose sha256 is not the recorded one (named).
    """
    base = Path(manifest).resolve().parent
    out = {}
    for name, entry in meshes_section(meshes, str(manifest)).items():    # fresh dicts, their paths str
        for key in MESH_FILES:
            file = base / entry[key]
            if not file.is_file():
                raise InputError(f"{manifest}: meshes.{name}.{key}: {file} is not a file (paths are relative to "
                                 "the manifest's folder)")
            if sha256_file(file) != str(entry[f"{key}_sha256"]):
                raise InputError(f"{manifest}: meshes.{name}.{key}: the sha256 of {file} is not the manifest's "
                                 f"{key}_sha256 ({entry[f'{key}_sha256']}); it is not the file the manifest names")
            entry[key] = str(file.resolve())
        out[name] = entry
    return out


def _without_paths(manifest: dict) -> dict:
    """The manifest without its meshes' paths (their sha256 stay): what a suite's id is made of, so that it does
    not depend on where the meshes lie."""
    if not manifest.get("meshes"):
        return manifest
    return {**manifest, "meshes": {n: {k: v for k, v in m.items() if k not in MESH_FILES}
                                   for n, m in manifest["meshes"].items()}}


def suite_id(name: str, manifest: dict, seed: int) -> str:
    """A hidden suite's id: ``<name>-<12 hex>`` of the seed and the manifest without its seed and name."""
    rest = {k: v for k, v in _without_paths(manifest).items() if k not in ("seed", "name")}
    return f"{name}-{json_digest({'hidden': IMPORTER_VERSION, 'seed': int(seed), 'manifest': rest})[:12]}"


def build(source, root, seed: int, name: str | None = None, workers: int = 1, progress: bool = True):
    """Generate a hidden suite's data (inputs and truth) into ``root/<id>`` from a manifest and a secret seed.

    Parameters
    ----------
    source : str or path
        A named segment suite (``demo-v1``) or a segment manifest file, procedural or naming real meshes (their
        paths relative to the manifest's folder, each checked against its recorded sha256; the private
        ``manifest.yaml`` names them by absolute path, and they are never copied).
    root : path
        The private suite data root (only the server reads it).
    seed : int
        The secret seed (:func:`new_seed`).
    name : str, optional
        The suite's name (default: the manifest's, with ``-hidden``).
    workers : int
    progress : bool

    Returns
    -------
    (LocalSuite, bool)
        The suite, and whether it was built now (False: it was already there).
    """
    from colonbench.benchmark import local_suites, verification
    from colonbench.benchmark.evaluate import select
    from colonbench.benchmark.fingerprint import segments_fingerprint
    from colonbench.shards.dataset import generate
    from colonbench.shards.schema import LOCK_NAME

    if not MIN_SEED <= int(seed) < MAX_SEED:
        raise InputError("a secret seed must be at least 2**40 and below 2**63")
    raw, manifest_name = _manifest(source)
    name = name or f"{manifest_name}-hidden"
    if not name.replace("-", "").replace("_", "").isalnum() or len(name) > 40:
        raise InputError(f"suite name {name!r}: letters, digits, '-' and '_' only, at most 40 characters")
    sid = suite_id(name, raw, seed)
    root = Path(root)
    target = root / sid
    if (target / local_suites.FILE).is_file():
        return local_suites.load(target), False
    if target.exists():
        raise InputError(f"{target}: exists and is not a built suite; remove it and build again")
    noise_seed = int(json_digest({"noise": int(seed)})[:15], 16)
    meshes = {n: {f"{k}_sha256": m[f"{k}_sha256"] for k in MESH_FILES} for n, m in (raw.get("meshes") or {}).items()}
    manifest = {**raw, "name": sid, "seed": int(seed),
                "description": f"hidden suite {sid}: {manifest_name}'s manifest with a secret seed (never publish "
                               "this file)"}
    root.mkdir(parents=True, exist_ok=True)
    tmp = root / f".{sid}.tmp-{os.getpid()}"
    shutil.rmtree(tmp, ignore_errors=True)
    t0 = time.perf_counter()
    try:
        generate(manifest, tmp, workers=workers, splits=["test"], progress=progress)
        lock = json.loads((tmp / LOCK_NAME).read_text())
        _, picks = select(tmp, "test", None)
        sha256, records = segments_fingerprint(tmp, picks, NOISE_MM, noise_seed)
        stub = local_suites.LocalSuite(name, IMPORTER_VERSION, "", "segments", "", len(records), sha256, 0.0,
                                       noise_mm=NOISE_MM, noise_seed=noise_seed, local_id=sid)
        published = verification.make(stub, lock, sha256, records)
        verification.write(published, tmp / local_suites.SIGNATURE_FILE)
        entry = {"format": local_suites.FORMAT, "format_version": local_suites.FORMAT_VERSION, "id": sid,
                 "name": name, "version": IMPORTER_VERSION, "task": "segments", "hidden": True,
                 "tests": f"a hidden test set: {len(records)} segments made from {manifest_name}'s manifest"
                          + (f" (real meshes: {', '.join(meshes)})" if meshes else "")
                          + " with a secret seed; its truth is kept on the evaluation server",
                 "samples": len(records), "sha256": sha256, "signature": verification.digest(published),
                 "noise_mm": list(NOISE_MM), "noise_seed": noise_seed,
                 "build_seconds": round(time.perf_counter() - t0, 1),
                 "importer": {"name": IMPORTER, "version": IMPORTER_VERSION},
                 "options": {"manifest": manifest_name, "split": "test"},
                 "source": {"meshes": meshes} if meshes else {}}
        (tmp / local_suites.FILE).write_text(json.dumps(entry, indent=1) + "\n")
        os.replace(tmp, target)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return local_suites.load(target), True


def build_c3vd(source, root, frames_every=None, width_px=None, workers: int = 1, intrinsics=None,
               progress: bool = True):
    """Build a C3VD download's segment suite into the private root through the C3VD importer
    (:func:`colonbench.benchmark.c3vd_suite.build`) and mark it hidden.

    Its id is the importer's (``c3vd-<12 hex>`` of the download's files and the options): its truth cannot be made
    again without the download, so keep the download as private as the folder. Its noise seed is the importer's
    fixed one; neither it nor the signature is published (:func:`seal_public`).

    Parameters
    ----------
    source : path
        The download's folder.
    root : path
        The private suite data root (only the server reads it).
    frames_every, width_px, workers, intrinsics, progress
        As :func:`colonbench.benchmark.c3vd_suite.build`.

    Returns
    -------
    (LocalSuite, bool)
        The suite, and whether it was built now (False: it was already there, now marked hidden).

    Raises
    ------
    InputError
        As :func:`colonbench.benchmark.c3vd_suite.build`; nothing is left in the root.
    """
    from colonbench.benchmark import c3vd_suite, local_suites

    suite, new = c3vd_suite.build(source, root, frames_every=frames_every, width_px=width_px, workers=workers,
                                  intrinsics=intrinsics, progress=progress)
    folder = Path(suite.folder)
    entry = local_suites.read_entry(folder)
    if not entry.get("hidden"):
        entry["hidden"] = True
        entry["tests"] = f"a hidden test set: {entry['tests']}; its truth is kept on the evaluation server"
        (folder / local_suites.FILE).write_text(json.dumps(entry, indent=1) + "\n")
    return local_suites.load(folder), new


def is_hidden(suite) -> bool:
    """Whether a suite is a hidden suite (its ``built-suite.json`` says ``"hidden": true``)."""
    from colonbench.benchmark import local_suites

    folder = getattr(suite, "folder", "")
    return bool(folder) and bool(local_suites.read_entry(Path(folder)).get("hidden"))


def served(roots) -> dict:
    """Every hidden suite under the private data roots, by id.

    Raises
    ------
    InputError
        A root is not a folder, holds no hidden suite, or two roots hold the same id.
    """
    from colonbench.benchmark import local_suites

    out = {}
    for root in roots:
        if not Path(root).is_dir():
            raise InputError(f"{root}: no such folder of hidden suites (colonbench suites build hidden --data DIR)")
        found = [s for s in local_suites.found(root) if is_hidden(s)]
        if not found:
            raise InputError(f"{root}: holds no hidden suite (colonbench suites build hidden --data {root})")
        for s in found:
            if s.id in out:
                raise InputError(f"{s.id} is in two of the --suites folders")
            out[s.id] = s
    return out


def sample_ids(suite) -> set[str]:
    """The ids of every evaluated cloud of a segment suite (what ``export`` names its inputs)."""
    from colonbench.benchmark.evaluate import select
    from colonbench.benchmark.exchange import sample_id

    _, picks = select(Path(suite.folder), suite.split, suite.limit)
    return {sample_id(n, i, s) for n, idx in picks for i in idx for s in suite.noise_mm}


def seal_public(folder, suite) -> dict:
    """Make an export of a hidden suite its published folder: ``suite.json`` cut down to what may be published
    (id, name, samples, noise levels, how to submit) and :data:`INPUTS_FILE` (every other file's sha256 and
    the digest of them all, ``inputs_sha256``), also recorded in the suite's private ``built-suite.json``.

    Returns
    -------
    dict
        :data:`INPUTS_FILE`'s content.
    """
    from colonbench.benchmark import local_suites
    from colonbench.benchmark.exchange import EXPORT_NAME

    folder = Path(folder)
    exported = json.loads((folder / EXPORT_NAME).read_text())
    public = {"suite": {"id": suite.id, "name": suite.name, "version": suite.version, "hidden": True,
                        "samples": suite.samples, "noise_mm": list(suite.noise_mm)},
              "track": exported.get("track", "points"), "inputs": exported["inputs"],
              "contract": "predict <sample_id>.json for every input (docs/formats.md), zip them, then colonbench "
                          f"submit --server URL --suite {suite.id} PRED_DIR (docs/server.md)"}
    (folder / EXPORT_NAME).write_text(json.dumps(public, indent=1) + "\n")
    files = {p.name: sha256_file(p) for p in sorted(folder.iterdir()) if p.is_file() and p.name != INPUTS_FILE}
    inputs = {"suite": suite.id, "files": files, "inputs_sha256": json_digest(files)}
    (folder / INPUTS_FILE).write_text(json.dumps(inputs, indent=1) + "\n")
    entry_path = Path(suite.folder) / local_suites.FILE
    entry = local_suites.read_entry(Path(suite.folder))
    entry["inputs_sha256"] = inputs["inputs_sha256"]
    entry_path.write_text(json.dumps(entry, indent=1) + "\n")
    return inputs
