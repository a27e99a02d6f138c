"""How much a model relies on the tube running along its grid's first axis: the same clouds, the grid's axes cycled.

    python scripts/probe_orientation.py data/train-wide --split validation --limit 48 --model small

The grid of a segment (:func:`colonbench.grid.fit_grid`) always puts the tube's axis first. A network
trained only on such grids (flips, but no exchange of axes) can learn to draw the tube along that axis
whatever the cloud says, and a bent segment, whose tube runs along several axes, then gets a tube drawn
across the colon. This script runs the completion method on every chosen cloud three times: with the
grid as fitted (the tube along axis 0), and with its rows cycled once and twice (the same cube, the tube
along axis 2, then axis 1). An orientation-free network errs the same in the three; the gap is the bias.
``colonbench train --transposes P`` trains against it (docs/training.md).

Prints per axis order the coverage MAE and bias (points) and the centerline precision / recall at 2 mm,
over the chosen samples and noise levels (the harness's noise draws, ``colonbench.benchmark.evaluate``).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from colonbench.benchmark.evaluate import select, noisy
from colonbench.benchmark.metrics import precision_recall
from colonbench.completion.method import CompletionMethod, from_heatmap, method_cloud
from colonbench.grid import fit_grid, grid_axes
from colonbench.heatmaps import input_from_points
from colonbench.shards.reader import Shard

#: The evaluate command's default noise seed, so that the noisy clouds are the harness's.
NOISE_SEED = 0
ORDERS = {"tube along axis 0 (as fitted)": 0, "tube along axis 2": 1, "tube along axis 1": 2}


def cycled_grid(points: np.ndarray, grid_options: dict, shift: int):
    """The grid :func:`colonbench.grid.fit_grid` gives ``points`` (mm) with ``grid_options``, its rows (axes) cycled
    ``shift`` times: the fitted first axis becomes axis 2 after one shift, axis 1 after two."""
    options = dict(grid_options)
    rotation = np.roll(grid_axes(points, options.pop("axes", "pca")), -shift, axis=0)
    return fit_grid(points, rotation=rotation, **options)


def estimate_on_cycled_grid(method: CompletionMethod, points: np.ndarray, shift: int):
    """The completion method's estimate of ``points`` (mm, a checked cloud) on its grid cycled ``shift`` times."""
    import torch

    predictor = method.predictor
    grid = cycled_grid(points, predictor.grid_options, shift)
    h_in, _ = input_from_points(grid, points)
    with torch.inference_mode():
        pred = predictor.net(torch.from_numpy(h_in[None, None]).to(predictor.device))[0, 0].float().cpu().numpy()
    return from_heatmap(np.clip(pred, 0.0, 1.0), grid, points, shell_level=method.shell_level, gaps=method.gaps)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("data", help="a generated dataset folder (colonbench generate)")
    ap.add_argument("--split", default="validation")
    ap.add_argument("--limit", type=int, default=None, help="evenly spread samples to take (default all)")
    ap.add_argument("--noise", default="0", help="comma-separated sigmas, mm (default 0)")
    ap.add_argument("--model", default=None, help="model file or shipped model name (default the shipped one)")
    args = ap.parse_args(argv)
    import torch

    torch.set_num_threads(1)
    sigmas = [float(s) for s in args.noise.split(",")]
    method = CompletionMethod(args.model)
    _, picks = select(args.data, args.split, args.limit)
    rows = {name: [] for name in ORDERS}
    for shard_name, indices in picks:
        with Shard(Path(args.data) / shard_name) as shard:
            for i in indices:
                geo = shard.geometry(i)
                for sigma in sigmas:
                    pts = method_cloud(noisy(geo["partial_points"], sigma, NOISE_SEED, shard_name, i))
                    for name, shift in ORDERS.items():
                        est = estimate_on_cycled_grid(method, pts, shift)
                        p, r = precision_recall(est.centerline, geo["centerline"], 2.0)
                        rows[name].append((100 * (est.coverage - geo["coverage"]), p, r))
    print(f"{args.data} {args.split}, {len(next(iter(rows.values())))} evaluations, model "
          f"{method.predictor.version}")
    print(f"{'grid':32s} {'MAE':>6s} {'bias':>6s} {'centerline P / R @2 mm':>24s}")
    for name, values in rows.items():
        a = np.array(values, float)
        print(f"{name:32s} {np.mean(np.abs(a[:, 0])):6.2f} {np.mean(a[:, 0]):+6.2f} "
              f"{np.nanmean(a[:, 1]):>15.2f} / {np.nanmean(a[:, 2]):.2f}")


if __name__ == "__main__":
    main()
