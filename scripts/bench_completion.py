"""Accuracy and speed of the completion method on test shards: per-stage seconds, MAE, precision/recall.

    python scripts/bench_completion.py data/paper --split test --limit 200 --model runs/small-cpu/best.safetensors
    python scripts/bench_completion.py data/paper --gt      # the GT target heatmap as prediction
    python scripts/bench_completion.py data/paper --tta 4   # the prediction averaged over 4 symmetries
    python scripts/bench_completion.py data/paper --method poisson   # any registered method

Noise (``--noise 0.5``) is added to the partial points from a seeded stream
per sample. One process, one torch thread (the "one CPU core" of the speed
target), the model loaded once. Prints figures only.
"""

from __future__ import annotations

import argparse
import resource
import sys
import time

import numpy as np
import pandas as pd

from colonbench import seeding
from colonbench.benchmark.metrics import segment_metrics
from colonbench.benchmark.summary import metric_columns, summarize
from colonbench.shards.reader import ShardDataset


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("data")
    ap.add_argument("--split", default="test")
    ap.add_argument("--limit", type=int, default=100, help="samples, spread evenly over the split")
    ap.add_argument("--model", help="model file (default: the shipped one)")
    ap.add_argument("--gt", action="store_true", help="feed the GT target heatmap instead of the network's")
    ap.add_argument("--tta", type=int, default=1, help="symmetries the network's prediction is averaged over")
    ap.add_argument("--method", default="completion", help="a registered method (colonbench methods)")
    ap.add_argument("--noise", type=float, default=0.0, help="Gaussian noise sigma on the inputs, mm")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--constant", type=float, help="also report the MAE of this constant guess (e.g. the mean "
                    "training coverage)")
    ap.add_argument("--json", help="also write the figures to this JSON file (for the model card)")
    args = ap.parse_args(argv)
    if args.gt and (args.method != "completion" or args.tta != 1):
        ap.error("--gt runs the steps on the exact heatmap: it takes neither --method nor --tta")

    import torch

    torch.set_num_threads(args.threads)
    from colonbench.completion.method import CompletionMethod, check_cloud, from_heatmap

    ds = ShardDataset(args.data, split=args.split, geometry=True)
    picks = np.unique(np.linspace(0, len(ds) - 1, min(args.limit, len(ds))).astype(int))
    if args.gt:
        method = None
    elif args.method == "completion":
        method = CompletionMethod(args.model, tta=args.tta)
    else:
        from colonbench.benchmark.registry import load_method

        method = load_method(args.method, model=args.model, tta=args.tta)
    rows, stages, true = [], {}, []
    setup = None
    if method is not None:
        # the second call sets the network up for inference (traced and optimized on the CPU): once per process;
        # the clouds are moved by 1 mm so that the timed loop does not find their predictions in the cache
        t = time.perf_counter()
        for k in picks[:2]:
            method.estimate(ds[int(k)]["partial_points"].astype(float) + 1.0)
        setup = time.perf_counter() - t
    t_all, t_estimate = time.perf_counter(), 0.0
    for k in picks:
        item = ds[int(k)]
        pts = item["partial_points"].astype(float)
        if args.noise > 0:
            pts = pts + seeding.rng(0, "eval-noise", int(round(args.noise * 1000)), int(k)).normal(0, args.noise,
                                                                                                  pts.shape)
        t = time.perf_counter()
        if args.gt:
            shard, i = ds.locate(int(k))
            est = from_heatmap(item["target"][0], shard.grid(i), check_cloud(pts))
        else:
            est = method.estimate(pts)
        t_estimate += time.perf_counter() - t
        for s, v in est.seconds.items():
            stages[s] = stages.get(s, 0.0) + v
        true.append(item["coverage"])
        rows.append({"method": "bench", "noise_mm": args.noise, "seconds": sum(est.seconds.values()), "error": "",
                     **segment_metrics(est.coverage, est.holes, est.centerline, item)})
    wall = time.perf_counter() - t_all
    n = len(rows)
    s = summarize(pd.DataFrame(rows)).iloc[0]
    print(f"{'GT heatmap' if args.gt else method.version} on {n} {args.split} samples of {args.data}, "
          f"noise {args.noise} mm")
    print(f"  coverage MAE {s['coverage_mae']:.2f} points, median {s['coverage_median']:.2f}, "
          f"bias {s['coverage_bias']:+.2f}, q95 {s['coverage_q95']:.2f}, undefined {s['coverage_undefined']}")
    constant_mae = None
    if args.constant is not None:
        constant_mae = 100 * float(np.mean(np.abs(args.constant - np.asarray(true))))
        print(f"  constant guess {args.constant:.3f}: MAE {constant_mae:.2f} points")
    metrics = metric_columns()
    for key in metrics:
        print(f"  {key:<28} mean {s[key + '_mean']:.3f}  median {s[key + '_median']:.3f}  "
              f"undefined {s[key + '_undefined']}")
    print("  seconds per segment by stage: " + ", ".join(f"{st} {v / n:.3f}" for st, v in stages.items())
          + f"; estimate {t_estimate / n:.3f}; with reading and scoring {wall / n:.3f} (threads: {args.threads})")
    if setup is not None:
        print(f"  first two calls, with the method's set-up (the network's, or open3d's import): {setup:.2f} s "
              "(once per process, not in the figures above)")
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"  peak memory {peak:.0f} MiB")
    if args.json:
        import json

        summary = {"data": str(args.data), "split": args.split, "samples": n, "noise_mm": args.noise,
                   "model": "GT heatmap" if args.gt else method.version, "threads": args.threads,
                   "coverage_mae_points": float(s["coverage_mae"]),
                   "coverage_median_abs_points": float(s["coverage_median"]),
                   "coverage_bias_points": float(s["coverage_bias"]),
                   "seconds_per_segment": {st: v / n for st, v in stages.items()}, "wall_per_segment": wall / n,
                   "estimate_per_segment": t_estimate / n, "first_two_calls_seconds": setup,
                   "peak_mib": peak, "constant_guess": args.constant, "constant_guess_mae_points": constant_mae,
                   "metrics_mean": {k: float(s[k + "_mean"]) for k in metrics},
                   "metrics_median": {k: float(s[k + "_median"]) for k in metrics}}
        with open(args.json, "w") as fh:
            json.dump(summary, fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
