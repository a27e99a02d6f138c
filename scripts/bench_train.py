"""Training throughput on a pack: heatmap making and training step per batch, samples/s, peak memory.

Usage::

    python scripts/bench_train.py PACK [--device cuda] [--network small] [--batch-sizes 8,32,64] [--steps 10] \
        [--erase 0.5] [--precision fp32,bf16] [--pool 1,2]

Uses the pack's validation split (its samples are only read). On a CUDA
device it first checks that the min-plus distance transform used there
equals the ``edt`` package's on one batch. ``--erase P`` times the batches
as ``colonbench train --erase P`` makes them (patches erased from a share of
the partial surfaces, their input heatmaps made again). ``--precision`` times
the training step in each arithmetic ``colonbench train --precision`` offers.
``--pool`` times the full grid (1) and the screening set-up (2: ``colonbench
train --pool 2``, the grids pooled to 32^3 and their heatmaps made once,
decision record 0326), both by default. Peak memory is the GPU's, or on the CPU the process's resident peak so far.
"""

from __future__ import annotations

import argparse
import resource
import time

import numpy as np
import torch

from colonbench.completion import packdata
from colonbench.completion.network import build_network, network_config, resolve_device
from colonbench.completion.train import PRECISIONS, memory_format, train_step


def sync(dev):
    if dev.type == "cuda":
        torch.cuda.synchronize(dev)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("pack")
    ap.add_argument("--device", default="auto")
    ap.add_argument("--network", default="small")
    ap.add_argument("--batch-sizes", default="4,16,32,64")
    ap.add_argument("--steps", type=int, default=10)
    ap.add_argument("--split", default="validation")
    ap.add_argument("--erase", type=float, default=0.0, help="share of samples with erased patches (as in training)")
    ap.add_argument("--precision", default="fp32", help=f"comma-separated, of {', '.join(PRECISIONS)} (default fp32)")
    ap.add_argument("--pool", default="1,2", help="comma-separated grid poolings: 1 full, 2 screening (default 1,2)")
    args = ap.parse_args()
    for pool in (int(p) for p in args.pool.split(",")):
        bench(args, pool)


def bench(args, pool: int) -> None:
    """Time heatmaps and training steps of one pooling of the pack's grids."""
    dev = resolve_device(args.device)
    t = time.perf_counter()
    split = packdata.PackSplit(args.pack, args.split, dev, cache=pool > 1, pool=pool)
    print(f"\n{len(split)} samples of {args.pack}:{args.split} on {dev} "
          f"({torch.cuda.get_device_name(dev) if dev.type == 'cuda' else 'CPU'}), grid {split.size}^3 "
          f"({'full' if pool == 1 else f'screening: pooled {pool} times, heatmaps made once'}), loaded in "
          f"{time.perf_counter() - t:.1f} s")
    if dev.type == "cuda":
        occ = split.grids(range(min(8, len(split)))).reshape(-1, *(split.size,) * 3)
        fast = packdata.distance_to(occ, "min-plus").cpu()
        ref = packdata.distance_to(occ.cpu(), "edt")
        print(f"min-plus vs edt on {len(occ)} grids: max |difference| {float((fast - ref).abs().max()):.2e} voxels")
    net = build_network(network_config(args.network)).to(dev, memory_format=memory_format(dev))
    opt = torch.optim.Adam(net.parameters(), lr=1e-3)
    print(f"network {args.network}: {sum(p.numel() for p in net.parameters()) / 1e6:.2f} M parameters")
    if args.erase:
        print(f"erasing patches from a share {args.erase} of the samples")
    print(f"{'precision':>9} {'batch':>5} {'heatmaps ms':>12} {'step ms':>9} {'samples/s':>10} {'peak MiB':>9}")
    rng = np.random.default_rng(0)
    for precision, bs in [(p, int(b)) for p in args.precision.split(",") for b in args.batch_sizes.split(",")]:
        if dev.type == "cuda":
            torch.cuda.reset_peak_memory_stats(dev)
        t_h = t_s = 0.0
        for step in range(args.steps + 2):
            idx = rng.choice(len(split), size=bs, replace=len(split) < bs)
            sync(dev)
            a = time.perf_counter()
            x, y = split.batch(idx, [packdata.erasure(0, step, int(i), args.erase) for i in idx])
            sync(dev)
            b = time.perf_counter()
            train_step(net, opt, x, y, precision)
            sync(dev)
            c = time.perf_counter()
            if step >= 2:  # two warm-up steps
                t_h += b - a
                t_s += c - b
        n = args.steps
        peak = (torch.cuda.max_memory_allocated(dev) if dev.type == "cuda"
                else resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024) / 2**20
        print(f"{precision:>9} {bs:>5} {1e3 * t_h / n:>12.1f} {1e3 * t_s / n:>9.1f} "
              f"{bs * n / (t_h + t_s):>10.1f} {peak:>9.0f}")


if __name__ == "__main__":
    main()
