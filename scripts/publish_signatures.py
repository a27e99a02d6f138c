"""Publish the suites' per-sample signatures: what every regenerated suite is checked against.

    python scripts/publish_signatures.py [--suites all] [--data DIR] [--workers 2]

Each suite's data is generated where missing; it must be bit-identical to the
published suite (its content hash, ``Suite.sha256``), since a signature
describes the published data and nothing else. Writes
``benchmark/signatures/<suite id>.json.gz`` (colonbench.benchmark.verification),
with each sample's cloud class (how its input was made, which says where a
redrawn cloud is accepted), and prints the digest to put in the suite's registry entry (``signature=``).
A suite's signature is written once, with its version; a new tolerance or
field is a new signature version (``cbs2``) for every suite.
"""

from __future__ import annotations

import argparse
import time

from colonbench.benchmark import signature, suites, verification
from colonbench.benchmark.fingerprint import surface_distances


def cloud_class(record: dict, distances: dict) -> str:
    """How a sample's input was made, as its signature records it: ``reconstruction`` (a video sample's fused
    surface), ``surface`` (every point on the observed true surface) or ``flawed`` (outliers, a second layer)."""
    if record["hole_model"] == "video":
        return "reconstruction"
    return "surface" if distances["input"] <= signature.TOLERANCES.surface_mm else "flawed"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--suites", default="all")
    ap.add_argument("--data", help="suite data folder (default: colonbench's cache)")
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    for suite in suites.parse(args.suites):
        t = time.perf_counter()
        data = suites.ensure_data(suite, args.data, workers=args.workers, progress=False)
        sha256, records, lock, where = suites.identity(suite, data)
        if sha256 != suite.sha256:
            raise SystemExit(f"{suite.id}: the data here hash to {sha256[:20]}..., not the published "
                             f"{suite.sha256[:20]}...: a signature is made from the published data only")
        for record, (name, i) in zip(records, where):
            record["cloud"] = cloud_class(record, surface_distances(data, name, i, task=suite.task))
        published = verification.make(suite, lock, sha256, records)
        path = verification.write(published, verification.SIGNATURE_DIR / f"{suite.id}.json.gz")
        print(f"{suite.id}: signature={verification.digest(published)!r} ({len(records)} samples, "
              f"{path.stat().st_size / 1024:.0f} KiB, {time.perf_counter() - t:.0f} s)", flush=True)


if __name__ == "__main__":
    main()
