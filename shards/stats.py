"""Dataset statistics for the lock file, and the paper's Fig. 2b (holes and coverage distributions) as a plot."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

from colonbench.shards.schema import HOLE_MODEL_NAMES

#: Coverage histogram bin edges (fraction).
COVERAGE_BINS = np.linspace(0.0, 1.0, 21)
#: Hole size histogram bin edges, % of the segment surface (as the paper's Fig. 2b).
HOLE_SIZE_BINS = np.array([0, 0.5, 1, 2, 3, 5, 7.5, 10, 15, 20, 30, 50, 100])


def shard_values(path) -> dict:
    """The per-sample values the statistics are made of, read from one shard (heatmaps are not read).

    Returns
    -------
    dict of arrays
        ``coverage`` (N,), ``holes`` (N,) holes per sample, ``hole_size_pct`` (H,)
        each hole's area in % of its segment's area, ``outside_grid`` (N,),
        ``voxel_mm`` (N,), ``noise_mm`` (N,), ``hole_model`` (N,) codes.
    """
    with h5py.File(path, "r") as h5:
        smp, seg = h5["samples"], h5["segments"]
        off = smp["hole_areas_mm2_offsets"][()]
        areas = smp["hole_areas_mm2"][()].astype(float)
        seg_area = seg["complete_area_mm2"][()][smp["segment"][()]]
        owner = np.repeat(np.arange(len(off) - 1), np.diff(off))
        return {"coverage": smp["coverage"][()], "holes": np.diff(off),
                "hole_size_pct": 100.0 * areas / seg_area[owner],
                "outside_grid": smp["outside_grid"][()].astype(float),
                "voxel_mm": np.linalg.norm(smp["grid_affine"][:, :3, 0], axis=1),
                "noise_mm": smp["noise_mm"][()].astype(float), "hole_model": smp["hole_model"][()]}


def quantiles(x) -> dict:
    """mean, 5 / 50 / 95 % quantiles, min and max of ``x`` ({} when empty)."""
    if len(x) == 0:
        return {}
    q = np.quantile(x, [0.05, 0.5, 0.95])
    return {"mean": float(np.mean(x)), "q05": float(q[0]), "median": float(q[1]), "q95": float(q[2]),
            "min": float(np.min(x)), "max": float(np.max(x))}


def summarize(values: list[dict]) -> dict:
    """JSON-ready statistics of one split from the :func:`shard_values` of its shards."""
    cat = {k: np.concatenate([v[k] for v in values]) if values else np.zeros(0) for k in
           ("coverage", "holes", "hole_size_pct", "outside_grid", "voxel_mm", "noise_mm", "hole_model")}
    hole_counts = np.bincount(cat["holes"].astype(int)) if len(cat["holes"]) else np.zeros(0, int)
    models, model_counts = np.unique(cat["hole_model"], return_counts=True)
    noise, noise_counts = np.unique(cat["noise_mm"], return_counts=True)
    return {
        "coverage": {**quantiles(cat["coverage"]), "histogram": {
            "edges": COVERAGE_BINS.tolist(), "counts": np.histogram(cat["coverage"], COVERAGE_BINS)[0].tolist()}},
        "holes_per_sample": {**quantiles(cat["holes"]), "counts": hole_counts.tolist()},
        "hole_size_pct": {**quantiles(cat["hole_size_pct"]), "histogram": {
            "edges": HOLE_SIZE_BINS.tolist(),
            "counts": np.histogram(np.clip(cat["hole_size_pct"], 0, 100), HOLE_SIZE_BINS)[0].tolist()}},
        "outside_grid": quantiles(cat["outside_grid"]),
        "voxel_mm": quantiles(cat["voxel_mm"]),
        "hole_models": {HOLE_MODEL_NAMES[int(m)]: int(c) for m, c in zip(models, model_counts)},
        "noise_mm": {f"{s:g}": int(c) for s, c in zip(noise, noise_counts)},
    }


def plot(split_stats: dict, path) -> Path:
    """Fig. 2b of the paper per split: holes per sample, hole sizes (% of segment), coverage."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    splits = list(split_stats)
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.6), constrained_layout=True)
    width = 0.8 / max(len(splits), 1)
    for j, split in enumerate(splits):
        st = split_stats[split]
        counts = np.asarray(st["holes_per_sample"]["counts"], float)
        x = np.arange(len(counts))
        axes[0].bar(x + (j - (len(splits) - 1) / 2) * width, counts / max(counts.sum(), 1), width, label=split)
        h = st["hole_size_pct"]["histogram"]
        c = np.asarray(h["counts"], float)
        xs = np.arange(len(c))
        axes[1].bar(xs + (j - (len(splits) - 1) / 2) * width, c / max(c.sum(), 1), width, label=split)
        h = st["coverage"]["histogram"]
        edges = np.asarray(h["edges"])
        c = np.asarray(h["counts"], float)
        axes[2].stairs(c / max(c.sum(), 1), 100 * edges, label=split)
    edges = HOLE_SIZE_BINS
    axes[1].set_xticks(np.arange(len(edges) - 1))
    axes[1].set_xticklabels([f"{a:g}-{b:g}" for a, b in zip(edges[:-1], edges[1:])], rotation=60, fontsize=7)
    axes[0].set(xlabel="holes per sample", ylabel="share of samples", title="number of holes")
    axes[1].set(xlabel="hole size, % of segment surface", ylabel="share of holes", title="hole sizes")
    axes[2].set(xlabel="coverage, %", ylabel="share of samples", title="coverage")
    for ax in axes:
        ax.legend(fontsize=8)
    path = Path(path)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
