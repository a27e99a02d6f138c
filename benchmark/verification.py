"""A suite's published signature, and a suite's data checked against it: bit-identical, within tolerance, or what
differs.

The published signature of a suite (``benchmark/signatures/<suite id>.json.gz``, made by
``scripts/publish_signatures.py`` from the published data) holds the suite's protocol, the hashes of its manifest
and generator configuration, the tolerances and one signature per sample
(:mod:`colonbench.benchmark.signature`); a paper cites the suite by its id and the signature's short digest.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from colonbench.benchmark.signature import TOLERANCES, VERSION, Tolerances, check_sample


#: Where the published signatures live in the package: ``<suite id>.json.gz``.
SIGNATURE_DIR = Path(__file__).resolve().parent / "signatures"


def canonical(published: dict) -> bytes:
    """The bytes a signature's digest is taken of: its JSON, keys sorted, no spaces."""
    return json.dumps(published, sort_keys=True, separators=(",", ":")).encode()


def digest(published: dict) -> str:
    """The short digest a paper cites a suite by: ``cbs1-`` and the first 12 hex digits of the signature's sha256."""
    return f"{VERSION}-{hashlib.sha256(canonical(published)).hexdigest()[:12]}"


def make(suite, lock: dict, sha256: str, records: list[dict], tolerances: Tolerances = TOLERANCES) -> dict:
    """A suite's signature as published: its protocol, the manifest and config hashes, tolerances and samples."""
    return {"format": "colonbench-suite-signature", "version": VERSION, "suite": suite.id,
            "manifest_sha256": lock.get("manifest_sha256"), "config_sha256": lock.get("config_sha256"),
            "noise_mm": [float(x) for x in suite.noise_mm], "noise_seed": int(suite.noise_seed),
            "sha256": sha256, "tolerances": asdict(tolerances), "samples": records}


def write(published: dict, path) -> Path:
    """Write a signature as gzipped JSON (no time stamp: the same signature gives the same bytes)."""
    import gzip

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as fh, gzip.GzipFile(fileobj=fh, mode="wb", mtime=0, filename="") as gz:
        gz.write(canonical(published))
    return path


def load(suite_id: str, expected: str | None = None) -> dict | None:
    """The published signature of a suite (None when the package has none).

    Raises
    ------
    InputError
        Its digest is not ``expected`` (the registry's): the file was changed without a new suite version.
    """
    import gzip

    path = SIGNATURE_DIR / f"{suite_id}.json.gz"
    if not path.is_file():
        return None
    published = json.loads(gzip.decompress(path.read_bytes()))
    if expected is not None and digest(published) != expected:
        from colonbench.errors import InputError

        raise InputError(f"{path}: its digest is {digest(published)}, the registry publishes {expected}: the file "
                         "was changed; reinstall colonbench")
    return published


@dataclass
class SuiteCheck:
    """A suite's data against its published signature.

    Attributes
    ----------
    suite : str
    sha256 : str
        The content hash found (``cb1-``).
    bit_identical : bool
        It is the published hash: the data are the published ones to the last rounded bit.
    faults : list of str
        What differs for the suite as a whole: its manifest or configuration, which samples it holds.
    samples : list of SampleCheck
    aggregate : list of str
        What differs over all samples together: the mean coverage difference, how many were decided at a tie.
    """

    suite: str
    sha256: str
    bit_identical: bool
    faults: list
    samples: list
    aggregate: list = field(default_factory=list)

    def at(self, level: str) -> list:
        """The samples at one level of :func:`~colonbench.benchmark.signature.check_sample`."""
        return [s for s in self.samples if s.level == level]

    @property
    def ties(self) -> int:
        """Samples decided otherwise at a near-tie."""
        return len(self.at("tie"))

    @property
    def redrawn(self) -> int:
        """Samples whose truth is the same but whose points were drawn anew on the same surface."""
        return len(self.at("redrawn"))

    @property
    def differing(self) -> list:
        """The samples that differ from their published signature."""
        return self.at("differs")

    @property
    def verified(self) -> bool:
        """The data are the published suite: within every tolerance (bit-identical data always are)."""
        return not self.faults and not self.differing and not self.aggregate

    @property
    def status(self) -> str:
        """``bit-identical``, ``within tolerance`` or ``differs``."""
        if not self.verified:
            return "differs"
        return "bit-identical" if self.bit_identical else "within tolerance"

    def first_difference(self) -> str:
        """The first thing that differs, in words ('' when verified)."""
        if self.faults:
            return self.faults[0]
        bad = self.differing
        if bad:
            return f"sample {bad[0].sample}: {bad[0].what}"
        return self.aggregate[0] if self.aggregate else ""

    def summary(self) -> str:
        """One line: the status, and what tolerance allowed or what differs."""
        if self.verified and self.bit_identical:
            return "bit-identical to the published data"
        if self.verified:
            mean = float(np.mean([abs(s.coverage_diff) for s in self.samples])) if self.samples else 0.0
            text = (f"within tolerance: {len(self.at('same'))} samples equal up to float noise, {self.ties} decided otherwise at a "
                    f"near-tie, {self.redrawn} with points redrawn on the same surface (mean |coverage difference| "
                    f"{mean:.1e})")
            for d in self.at("diverged"):
                text += f"; {d.sample}: {d.what}"
            return text
        more = len(self.faults) + len(self.differing) + len(self.aggregate) - 1
        return f"differs: {self.first_difference()}" + (f" (and {more} more)" if more > 0 else "")


def check_suite(published: dict, lock: dict, sha256: str, records: list[dict], surface=None, noise_mm=None,
                noise_seed: int = 0) -> SuiteCheck:
    """Compare a suite's data (its lock, content hash and per-sample signatures) with the published signature.

    ``surface(k)``: the on-surface distances of sample ``k`` (:func:`check_sample`'s ``surface``); ``noise_mm`` and
    ``noise_seed``: the noise protocol the records were made with (checked against the published one where given).
    """
    tol = Tolerances(**published["tolerances"])
    faults = []
    for key, what in (("manifest_sha256", "manifest"), ("config_sha256", "generator configuration")):
        if lock.get(key) != published[key]:
            faults.append(f"made from another {what} ({key} {str(lock.get(key))[:12]}..., published "
                          f"{published[key][:12]}...)")
    if noise_mm is not None:
        for key, value in (("noise_mm", [float(x) for x in noise_mm]), ("noise_seed", int(noise_seed))):
            if value != published[key]:
                faults.append(f"checked with {key} {value}, published {published[key]} (another noise protocol)")
    pub = published["samples"]
    checks = []
    for k, (found, want) in enumerate(zip(records, pub)):
        if found["sample"] != want["sample"]:
            faults.append(f"sample {k + 1} is {found['sample']}, published {want['sample']} (samples dropped, "
                          "added or reordered)")
            break
        checks.append(check_sample(found, want, tol, None if surface is None else (lambda k=k: surface(k))))
    if len(records) != len(pub) and not any("reordered" in f for f in faults):
        faults.append(f"{len(records)} samples, published {len(pub)} (first "
                      f"{'extra' if len(records) > len(pub) else 'missing'}: "
                      f"{(records if len(records) > len(pub) else pub)[min(len(records), len(pub))]['sample']})")
    aggregate = []
    if checks:
        mean = float(np.mean([abs(c.coverage_diff) for c in checks]))
        if not mean <= tol.coverage_mean:
            worst = max(checks, key=lambda c: abs(c.coverage_diff))
            aggregate.append(f"mean |coverage difference| over the samples is {mean:.2e}, more than near-ties make "
                             f"({tol.coverage_mean:g}); the largest: sample {worst.sample}, {worst.coverage_diff:+.2e}")
        ties = sum(c.level in ("tie", "diverged") for c in checks)
        diverged = [c for c in checks if c.level == "diverged"]
        if len(diverged) > max(1, int(tol.diverged_share * len(pub))):
            aggregate.append(f"{len(diverged)} samples went another way after a near-tie, more than "
                             f"{max(1, int(tol.diverged_share * len(pub)))} of {len(pub)} may; first "
                             f"{diverged[0].sample}: {diverged[0].what}")
        if ties > tol.tie_share * len(pub):
            first = next(c for c in checks if c.level in ("tie", "diverged"))
            aggregate.append(f"{ties} of {len(pub)} samples were decided otherwise at a near-tie, more than float "
                             f"noise makes ({tol.tie_share:.0%}): the generator differs; the first: sample {first.sample}, "
                             f"{first.what}")
    return SuiteCheck(published["suite"], sha256, sha256 == published["sha256"], faults, checks, aggregate)


def record_problems(record: dict, suite) -> list[str]:
    """Why a run's suite record (``suite`` in ``run.json``) does not show data verified against ``suite``'s published
    signature, bit-identical or within tolerance; empty where it does. The one check behind a submission
    (:mod:`colonbench.benchmark.submitted`) and a within-tolerance publication of shipped rows
    (:func:`colonbench.benchmark.shipped.publish`, decision record 0327)."""
    problems = []
    if not record.get("verified") or record.get("check") not in ("bit-identical", "within tolerance"):
        problems.append(f"its data did not verify against {suite.id}'s published signature (check: "
                        f"{record.get('check') or 'none'}): evaluate on the published suite, without "
                        "--allow-unverified")
    if record.get("signature") != suite.signature:
        problems.append(f"its suite record names the signature {record.get('signature')!r}, {suite.id}'s published "
                        f"one is {suite.signature}")
    if record.get("published_sha256") != suite.sha256:
        problems.append(f"its suite record names the published content hash {record.get('published_sha256')!r}, "
                        f"{suite.id}'s is {suite.sha256}")
    claims = record.get("check") == "bit-identical" or record.get("bit_identical")
    if claims and record.get("sha256") != suite.sha256:
        problems.append(f"its suite record says bit-identical, but its content hash (sha256 {record.get('sha256')!r})"
                        f" is not {suite.id}'s ({suite.sha256})")
    return problems
