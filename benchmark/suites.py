"""The benchmark's named, versioned suites: what each scores, on which data, and its published content hash.

A suite is a manifest, a split, a selection of its samples, a noise protocol
and the metrics reported on it. Its data is made again from the manifest on
the user's machine (``colonbench benchmark`` and ``colonbench export`` do it
when it is missing) and checked against the content hash published here
(:mod:`colonbench.benchmark.fingerprint`): inputs and truth, rounded to 1 µm
and 1e-6. A change of the generator that moves a suite's data must come with
a new version of that suite (``paper-v2``): the suite hash tests fail until
it does.

The registry is data (:data:`SUITES`); ``colonbench suites`` prints it.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

from colonbench.errors import InputError, did_you_mean

SEGMENT_METRICS = ("coverage MAE with 95 % bootstrap interval, median, bias, q95 (points)",
                   "holes and centerline precision / recall at 1 and 2 mm")
COLON_METRICS = ("segment coverage MAE per track (points)", "whole-colon coverage |error| (points)",
                 "map centerline precision / recall at 2 mm")


@dataclass(frozen=True)
class Suite:
    """One named, versioned suite.

    Attributes
    ----------
    name : str
        ``paper``, ``real``, ...; with its version the id ``paper-v1``.
    version : int
    manifest : str
        Manifest file name in the project's ``data_manifests/``.
    task : str
        ``segments`` (one partial segment per sample) or ``colon`` (whole partial colons, mapped).
    tests : str
        What the suite tests, one sentence.
    samples : int
        Evaluated samples: segments, or whole-colon reconstructions.
    sha256 : str
        The published content hash (:mod:`colonbench.benchmark.fingerprint`): bit-identical data only.
    generate_seconds : float
        Time to generate its data on the project's 2-core machine (``--workers 2``), s.
    split : str
    limit : int or None
        Only this many samples, spread evenly over the split (``evaluate --limit``).
    noise_mm : tuple of float
        Input noise sigmas, mm.
    noise_seed : int
    contexts_mm : tuple of float
        Whole colons: the context margins of the tracks, mm (0 = segment-only).
    segment_mm : float
        Whole colons: the maps' segment length, mm.
    metrics : tuple of str
    signature : str
        Digest of the published per-sample signature (:mod:`colonbench.benchmark.signature`), the suite's
        identity on any machine: ``cbs1-<12 hex>``.
    archive_url, archive_sha256 : str or None
        Where a frozen archive of the suite's data is published, and its sha256
        (:mod:`colonbench.benchmark.archive`): ``colonbench benchmark`` fetches it instead of generating.
    """

    name: str
    version: int
    manifest: str
    task: str
    tests: str
    samples: int
    sha256: str
    generate_seconds: float
    split: str = "test"
    limit: int | None = None
    noise_mm: tuple = (0.0, 0.5)
    noise_seed: int = 0
    contexts_mm: tuple = ()
    segment_mm: float = 60.0
    metrics: tuple = field(default=SEGMENT_METRICS)
    signature: str = ""
    archive_url: str | None = None
    archive_sha256: str | None = None

    @property
    def id(self) -> str:
        """``<name>-v<version>``."""
        return f"{self.name}-v{self.version}"

    @property
    def headline_track(self) -> str | None:
        """A whole-colon suite's track in cross-suite tables: the widest context (what ``colonbench map``
        reports); None for a segment suite."""
        if self.task != "colon":
            return None
        from colonbench.benchmark.colon_evaluate import track_name

        return track_name(max(self.contexts_mm))

    @property
    def citation(self) -> str:
        """How a paper names the suite: ``real-v1 (cbs1-3f2a9c81e0d4)``, its id and published signature's digest."""
        return f"{self.id} ({self.signature})"

    def record(self, check) -> dict:
        """What a run stores of the suite it evaluated: id, name, version, signature, the check's outcome (verified,
        bit-identical or within tolerance, samples decided otherwise at a near-tie, redrawn on the same surface or
        diverged) and the hash found beside the published one."""
        return {"id": self.id, "name": self.name, "version": self.version, "signature": self.signature,
                "verified": bool(check.verified), "check": check.status, "bit_identical": bool(check.bit_identical),
                "tie_samples": int(check.ties), "redrawn_samples": int(check.redrawn),
                "diverged_samples": len(check.at("diverged")), "sha256": check.sha256, "published_sha256": self.sha256}


SUITES: tuple[Suite, ...] = (
    Suite("demo", 1, "demo.yaml", "segments",
          "a smoke test: 24 segments (5, 6, 7 cm) of 2 paper-style procedural colons, camera and sphere holes; "
          "checks that a method runs, in seconds", 24,
          "cb1-a13629a7324018e9d8ecb09cea6be2586b5f45b4da3844544cd522dfa00dedd9", 9.0,
          signature="cbs1-0cd018e664f0"),
    Suite("paper", 1, "paper.yaml", "segments",
          "the paper's synthetic protocol: 400 of the 1200 test segments (5, 6, 7 cm) of 40 procedural colons, "
          "spread evenly, camera and sphere holes", 400,
          "cb1-19be7d96a87e397a2ef9b1e5ac22c7f85b639359e40bccad1dcb4b43dbbbc9ba", 267.0, limit=400,
          signature="cbs1-9aafe313d9e0"),
    Suite("wide", 1, "wide.yaml", "segments",
          "colons, clouds and holes unlike the paper's: radii 10-40 mm, flat to deep folds, elliptic sections, "
          "diverticula, 0.5-8 points/mm^2, outliers, double layers, unseen ends; 144 segments of 12 colons", 144,
          "cb1-3658de0d12ed931028b451af9bfdbab14c646faeeaa407285d2894691a6b832e", 86.0,
          signature="cbs1-76f58e24194d"),
    Suite("real", 1, "real-test.yaml", "segments",
          "a real CT colon no shipped model was trained on (gca00060, Gut Cell Atlas, CC BY 4.0): 86 segments, "
          "camera and sphere holes", 86,
          "cb1-f464a6e95047c6c732cb9c72cd125d268a792b49c795ac033238b8ce0a0af301", 33.0,
          signature="cbs1-7816a88abc21"),
    Suite("video", 1, "video.yaml", "segments",
          "reconstruction-like partials: rendered withdrawals with degraded depth and drifting poses, fused by "
          "TSDF; 36 segments of 6 paper-style test colons", 36,
          "cb1-43638daac6027213e0d6048ecfce64a82d283c54e5ee3df49ea4e6f74aedec27", 84.0,
          signature="cbs1-ec4df20fabc8"),
    Suite("colon", 1, "colon-test.yaml", "colon",
          "whole colons (4 procedural and the real gca00060, 2 reconstructions each) mapped into 60 mm segments "
          "by colonbench map, scored on exact per-face truth, segment-only and in-context tracks", 10,
          "cb1-70ba1412f3455a7ba053f52a2cacc2265521ac4ad6edbb48145d89fd755c7cc1", 51.0,
          contexts_mm=(0.0, 2.5), metrics=COLON_METRICS,
          signature="cbs1-067f84407832"),
)


def latest() -> dict[str, Suite]:
    """The newest version of every suite, by name."""
    out: dict[str, Suite] = {}
    for s in SUITES:
        if s.name not in out or s.version > out[s.name].version:
            out[s.name] = s
    return out


def get(name, root=None) -> Suite:
    """A suite by id (``paper-v1``) or name (``paper``: its newest version); a :class:`Suite` as it is. A suite
    built on this machine (:mod:`colonbench.benchmark.local_suites`, ``colonbench suites build``) is found by its
    id, or by its name where one of that name is built, under ``root`` (default :func:`default_data_root`).

    Raises
    ------
    InputError
        No such suite (the message lists them).
    """
    if isinstance(name, Suite):
        return name
    name = name.strip()
    for s in SUITES:
        if name in (s.id,):
            return s
    if name in latest():
        return latest()[name]
    from colonbench.benchmark import local_suites

    local = local_suites.lookup(name, root)
    if local is not None:
        return local
    built = [s.id for s in local_suites.found(root)]
    close = did_you_mean(name, [s.id for s in SUITES] + list(latest()) + built)
    # a suite built from a download (c3vd-<id>) exists only once built: say how, where none of that kind is built
    kind = name.split("-", 1)[0]
    how = (f"; a {kind} suite is built from your download first: colonbench suites build {kind} --from DIR"
           if kind in local_suites.DOWNLOADS and not any(b.startswith(kind + "-") for b in built) else "")
    raise InputError(f"unknown suite {name!r}{close}; the suites are {', '.join(s.id for s in SUITES)} (or all)"
                     + (f", and built here {', '.join(built)}" if built else "") + how)


def parse(text, root=None) -> list[Suite]:
    """``all`` (every newest suite), comma-separated ids/names, or a list of ids, names or suites; in the order
    given, each once (a locally built suite by its id or name under ``root``: :func:`get`; ``all`` holds none)."""
    names = [n.strip() for n in text.split(",") if n.strip()] if isinstance(text, str) else list(text)
    if not names:
        raise InputError("no suites given")
    if names == ["all"]:
        return list(latest().values())
    out = []
    for n in names:
        s = get(n, root)
        if s not in out:
            out.append(s)
    return out


def manifest_dir() -> Path:
    """The folder of the project's manifests (``data_manifests/``, installed as ``colonbench.data_manifests``)."""
    import colonbench.data_manifests as pkg

    return Path(pkg.__file__).parent


def manifest_path(suite: Suite) -> Path:
    """The manifest file of a suite."""
    return manifest_dir() / suite.manifest


def default_data_root() -> Path:
    """Where suite data is cached: ``$COLONBENCH_DATA``, else ``$XDG_CACHE_HOME/colonbench/suites``, else
    ``~/.cache/colonbench/suites``."""
    if os.environ.get("COLONBENCH_DATA"):
        return Path(os.environ["COLONBENCH_DATA"]).expanduser()
    cache = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(cache) / "colonbench" / "suites"


def data_dir(suite: Suite, root=None) -> Path:
    """The data folder of a suite under ``root`` (default :func:`default_data_root`): ``root/<suite id>``; a
    locally built suite's own folder."""
    if getattr(suite, "folder", ""):
        return Path(suite.folder)
    return Path(root if root is not None else default_data_root()) / suite.id


def ensure_data(suite: Suite, root=None, workers: int = 1, scheduler=None, progress: bool = True) -> Path:
    """The suite's data folder: fetched from its published archive where the registry names one and nothing is
    cached (:mod:`colonbench.benchmark.archive`), else generated (or finished) from its manifest, resumable like
    ``generate``; a suite built from a download (:mod:`colonbench.benchmark.local_suites`) is never made here:
    its folder, or an error saying to build it again."""
    from colonbench.shards.dataset import LOCK_NAME, generate

    out = data_dir(suite, root)
    lock = out / LOCK_NAME
    if lock.is_file():
        import json

        try:
            done = json.loads(lock.read_text())
        except ValueError:
            done = {}
        if suite.split in done.get("splits", []) and not any(m.startswith(f"{suite.split}/")
                                                             for m in done.get("missing", [])):
            return out
    if getattr(suite, "folder", ""):   # built from a download, never generated
        raise InputError(f"{out}: the built suite {suite.id} is incomplete (its {LOCK_NAME} is missing or names "
                         "missing shards); build it again (colonbench suites build)")
    if suite.archive_url and not out.exists():
        from colonbench.benchmark.archive import fetch

        return fetch(suite, suite.archive_url, suite.archive_sha256, root, progress=progress)
    generate(manifest_path(suite), out, workers=workers, scheduler=scheduler, splits=[suite.split],
             progress=progress)
    return out


def identity(suite: Suite, data) -> tuple[str, list[dict], dict, list]:
    """A suite's data folder as its identity is checked: content hash, per-sample signatures, the lock and the
    samples' places (shard name, index), in order."""
    from colonbench.benchmark import fingerprint as fp
    from colonbench.benchmark.evaluate import read_lock, select

    _, picks = select(data, suite.split, suite.limit)
    fn = fp.colons_fingerprint if suite.task == "colon" else fp.segments_fingerprint
    sha256, records = fn(data, picks, suite.noise_mm, suite.noise_seed)
    return sha256, records, read_lock(Path(data)), [(name, i) for name, indices in picks for i in indices]


def fingerprint(suite: Suite, data) -> str:
    """The content hash of a suite's data folder (:mod:`colonbench.benchmark.fingerprint`): equal to the
    published one only for bit-identical data."""
    return identity(suite, data)[0]


def published_signature(suite: Suite) -> dict:
    """The suite's published per-sample signature (:mod:`colonbench.benchmark.signature`)."""
    from colonbench.benchmark import local_suites, verification

    if isinstance(suite, local_suites.LocalSuite):
        return local_suites.signature(suite)
    published = verification.load(suite.id, suite.signature)
    if published is None:
        raise InputError(f"this colonbench has no published signature of {suite.id} "
                         f"(benchmark/signatures/{suite.id}.json.gz): reinstall it")
    return published


def check(suite: Suite, data):
    """A suite's data folder against its published signature: a
    :class:`~colonbench.benchmark.verification.SuiteCheck` (bit-identical, within tolerance, or what differs)."""
    from colonbench.benchmark.fingerprint import surface_distances
    from colonbench.benchmark.verification import check_suite

    sha256, records, lock, where = identity(suite, data)
    return check_suite(published_signature(suite), lock, sha256, records,
                       surface=lambda k: surface_distances(data, *where[k], task=suite.task), noise_mm=suite.noise_mm,
                       noise_seed=suite.noise_seed)


def verify(suite: Suite, data, allow_unverified: bool = False) -> dict:
    """Check a suite's data against its published signature; the record a run keeps (:meth:`Suite.record`).

    Raises
    ------
    InputError
        The data differ from the published suite beyond its tolerances and ``allow_unverified`` is not set; the
        message names the first sample that differs and by how much.
    """
    result = check(suite, data)
    if not result.verified and not allow_unverified:
        raise InputError(
            f"{data} does not hold suite {suite.id}: {result.first_difference()} (docs/benchmark.md, Verified "
            "suites). Regenerate it into an empty folder, or pass --allow-unverified to evaluate it anyway; the "
            "results then say 'unverified'")
    return suite.record(result)


def match(identity: dict, noise_mm, noise_seed: int, task: str, data=None) -> Suite | None:
    """The suite a run's data and protocol are, if any: the same manifest name, split, sample count, noise levels
    and noise seed (:func:`colonbench.benchmark.evaluate.select`'s identity); where ``data`` is a locally built
    suite's folder, that suite, its id as the manifest name."""
    if data is not None:
        from colonbench.benchmark import local_suites

        local = local_suites.load(data)
        if (local is not None and local.id == identity.get("manifest_name") and local.split == identity.get("split")
                and local.samples == identity.get("samples") and local.task == task
                and sorted(float(x) for x in noise_mm) == sorted(local.noise_mm)
                and int(noise_seed) == local.noise_seed):
            return local
    for s in SUITES:
        manifest = manifest_path(s)
        name = _manifest_name(manifest)
        if (name == identity.get("manifest_name") and s.split == identity.get("split")
                and s.samples == identity.get("samples") and s.task == task
                and sorted(float(x) for x in noise_mm) == sorted(s.noise_mm) and int(noise_seed) == s.noise_seed):
            return s
    return None


_NAMES: dict = {}


def _manifest_name(path: Path) -> str | None:
    if path not in _NAMES:
        import yaml

        try:
            _NAMES[path] = (yaml.safe_load(path.read_text()) or {}).get("name")
        except (OSError, yaml.YAMLError):
            _NAMES[path] = None
    return _NAMES[path]
