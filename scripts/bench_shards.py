"""Benchmark shard generation: samples/s per core, time per stage, peak memory, bytes per sample and per
field, what a reader pays to make the heatmaps, and the projected time of a whole manifest.

    python scripts/bench_shards.py                       # a few shards of demo.yaml, one process
    python scripts/bench_shards.py --manifest data_manifests/paper.yaml --shards 2
    python scripts/bench_shards.py --manifest data_manifests/paper.yaml --shards 2 --format 1   # format 1

Prints figures only; nothing here is a test.
"""

from __future__ import annotations

import argparse
import resource
import sys
import tempfile
import time
from pathlib import Path

import h5py
import numpy as np

from colonbench.heatmaps import distance_to
from colonbench.shards.build import build_shard
from colonbench.shards.manifest import load, units
from colonbench.shards.reader import Shard
from colonbench.shards.schema import FORMAT_VERSION

ROOT = Path(__file__).resolve().parents[1]


def edt_floor(reps: int = 20) -> float:
    """Seconds for the three 64^3 distance transforms of one sample (median of ``reps``)."""
    rng = np.random.default_rng(0)
    occ = rng.random((64, 64, 64)) < 0.02
    times = []
    for _ in range(reps):
        t = time.perf_counter()
        for _ in range(3):
            distance_to(occ)
        times.append(time.perf_counter() - t)
    return float(np.median(times))


def field_bytes(paths) -> dict:
    """Stored (compressed) bytes per dataset, summed over shards."""
    out = {}
    for p in paths:
        with h5py.File(p, "r") as h5:
            def visit(name, obj):
                if isinstance(obj, h5py.Dataset):
                    out[name] = out.get(name, 0) + obj.id.get_storage_size()
            h5.visititems(visit)
    return out


def projected_counts(resolved) -> tuple[int, int, int]:
    """(shards, segments, samples) of a manifest, assuming every colon has enough windows."""
    n_shards = n_seg = n_smp = 0
    n_len = len(resolved["config"]["segments"]["lengths_mm"])
    for s in resolved["splits"].values():
        shards = s["colons"]["count"] * n_len
        per = s["segments_per_length"] or 20
        n_shards += shards
        n_seg += shards * per
        n_smp += shards * per * s["permutations"]
    return n_shards, n_seg, n_smp


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--manifest", default=str(ROOT / "data_manifests" / "demo.yaml"))
    ap.add_argument("--shards", type=int, default=3, help="shards to build (from the train split first)")
    ap.add_argument("--project", default=str(ROOT / "data_manifests" / "paper.yaml"),
                    help="manifest whose total time to project from the measured stage times")
    ap.add_argument("--format", type=int, default=FORMAT_VERSION, choices=(1, 2),
                    help="shard format to write (1: heatmaps stored, as before format 2)")
    args = ap.parse_args(argv)

    resolved = load(args.manifest)
    todo = units(resolved)[: args.shards]
    floor = edt_floor()
    stages, n_samples, n_segments, files = {}, 0, 0, []
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        for u in todo:
            info = build_shard(resolved, u, tmp, version=args.format)
            for k, v in info["seconds"].items():
                stages[k] = stages.get(k, 0.0) + v
            n_samples += info["samples"]
            n_segments += info["segments"]
            files.append(Path(tmp) / u.name)
        wall = time.perf_counter() - t0
        sizes = field_bytes(files)
        total_bytes = sum(f.stat().st_size for f in files)
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        with Shard(files[0]) as shard:
            t = time.perf_counter()
            for i in range(len(shard)):
                shard.heatmaps(i)
            read_ms = (time.perf_counter() - t) / len(shard) * 1000
    print(f"manifest {resolved['name']}: {len(todo)} shards, {n_segments} segments, {n_samples} samples, one process")
    print(f"  wall {wall:.1f} s -> {n_samples / wall:.2f} samples/s per core, {wall / n_samples * 1000:.0f} ms/sample")
    print("  stage                  total s   per sample ms")
    for k in ("colon", "segment", "sample", "grids", "write"):
        v = stages.get(k, 0.0)
        print(f"  {k:<20} {v:9.2f} {v / n_samples * 1000:13.1f}")
    print(f"  distance-transform floor (3 x edt 64^3): {floor * 1000:.1f} ms/sample")
    print(f"  a reader's heatmaps (Shard.heatmaps, format {args.format}): {read_ms:.1f} ms/sample")
    print(f"  peak memory (max RSS): {peak:.0f} MiB")
    print(f"  bytes per sample: {total_bytes / n_samples / 1024:.1f} KiB (files), by field (compressed):")
    for name, b in sorted(sizes.items(), key=lambda kv: -kv[1])[:10]:
        print(f"    {name:<34} {b / n_samples / 1024:8.1f} KiB/sample")

    proj = load(args.project)
    shards, segs, smps = projected_counts(proj)
    per_shard = stages.get("colon", 0.0) / len(todo)
    per_seg = stages.get("segment", 0.0) / n_segments
    per_smp = sum(stages.get(k, 0.0) for k in ("sample", "grids", "write")) / n_samples
    core_s = shards * per_shard + segs * per_seg + smps * per_smp
    print(f"projection for {proj['name']}: {shards} shards, {segs} segments, {smps} samples -> "
          f"{core_s / 3600:.1f} core-hours ({core_s / 3600 / 2:.1f} h on 2 cores, {core_s / 60 / 32:.0f} min on 32), "
          f"{smps * total_bytes / n_samples / 2**30:.1f} GiB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
