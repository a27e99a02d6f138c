"""The benchmark's figures, headless (matplotlib Agg), from stored runs only.

* ``boxplots.png``, like the paper's Fig. 4: per noise level, box plots by
  method of hole and centerline precision and recall at the largest metric
  threshold, and of the absolute coverage error (percentage points).
  Reference rows (given ground truth) are drawn grey.
* ``scatter.png``: estimated against true coverage, one panel per method,
  noise levels in colour.
* ``triplets-<method>.png``, like the paper's Fig. 5: for the example
  segments a run kept (``evaluate --examples``), the input cloud; the
  completed mesh with hole vertices red; the completed mesh with the
  estimated centerline red (GT centerline black, dashed). Geometry is in
  mm, turned so that the segment's end-to-end direction runs along x.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from colonbench.grid import principal_axes
from colonbench.reports.pictures import axes_3d, set_equal, draw_surface

COLORS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e")


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def boxplots(results: pd.DataFrame, tab: pd.DataFrame, path, threshold_mm: float = 2.0) -> Path:
    """Fig. 4: per noise level, box plots by method of P/R (holes, centerline) and |coverage error|."""
    plt = _plt()
    noises = sorted(results["noise_mm"].unique())
    order = list(dict.fromkeys(tab["method"]))  # ranked, references last
    ref = dict(zip(tab["method"], tab["reference"]))
    t = f"{threshold_mm:g}mm"
    panels = [(f"holes_precision_{t}", f"holes precision @{threshold_mm:g} mm"),
              (f"holes_recall_{t}", f"holes recall @{threshold_mm:g} mm"),
              (f"centerline_precision_{t}", f"centerline precision @{threshold_mm:g} mm"),
              (f"centerline_recall_{t}", f"centerline recall @{threshold_mm:g} mm"),
              ("abs_error", "|coverage error|, percentage points")]
    fig, axes = plt.subplots(len(noises), len(panels), figsize=(3.4 * len(panels), 3.3 * len(noises)),
                             squeeze=False)
    df = results.assign(abs_error=100 * results["coverage_error"].abs())
    for r, noise in enumerate(noises):
        g = df[df["noise_mm"] == noise]
        for c, (col, title) in enumerate(panels):
            ax = axes[r, c]
            data = [g.loc[g["method"] == m, col].dropna().to_numpy() for m in order]
            pos = [k for k, d in enumerate(data) if len(d)]
            if pos:
                bp = ax.boxplot([data[k] for k in pos], positions=pos, widths=0.6, showfliers=True,
                                flierprops={"markersize": 2}, patch_artist=True)
                for k, box in zip(pos, bp["boxes"]):
                    box.set_facecolor("#bbbbbb" if ref[order[k]] else "#9ecae1")
            ax.set_xticks(range(len(order)))
            ax.set_xticklabels([m + ("*" if ref[m] else "") for m in order], rotation=60, ha="right", fontsize=7)
            ax.set_xlim(-0.6, len(order) - 0.4)
            if col != "abs_error":
                ax.set_ylim(-0.03, 1.03)
            ax.set_title(f"{title}, noise {noise:g} mm", fontsize=8)
            ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def scatter(results: pd.DataFrame, tab: pd.DataFrame, path) -> Path:
    """Estimated against true coverage, one panel per method, noise levels in colour."""
    plt = _plt()
    order = list(dict.fromkeys(tab["method"]))
    n = len(order)
    cols = min(4, n)
    rows = int(np.ceil(n / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 3.2 * rows), squeeze=False)
    for k, m in enumerate(order):
        ax = axes[k // cols, k % cols]
        g = results[results["method"] == m]
        for j, (noise, h) in enumerate(g.groupby("noise_mm")):
            ax.scatter(h["true_coverage"], h["coverage"], s=6, alpha=0.6, color=COLORS[j % len(COLORS)],
                       label=f"noise {noise:g} mm")
        ax.plot([0, 1], [0, 1], color="k", lw=0.8)
        ax.set_xlim(0, 1.02)
        ax.set_ylim(0, 1.02)
        ax.set_aspect("equal")
        ax.set_title(m + (" (reference)" if bool(tab.loc[tab["method"] == m, "reference"].iloc[0]) else ""),
                     fontsize=9)
        ax.set_xlabel("true coverage", fontsize=8)
        ax.set_ylabel("estimated coverage", fontsize=8)
        if k == 0:
            ax.legend(fontsize=7, loc="upper left")
    for k in range(n, rows * cols):
        axes[k // cols, k % cols].axis("off")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def _side_view(points: np.ndarray, centerline: np.ndarray) -> np.ndarray:
    """(3, 3) rows: the segment's end-to-end direction first (along x in the plots), then the cloud's other axes."""
    axes = principal_axes(points)
    cl = np.asarray(centerline, float).reshape(-1, 3)
    chord = cl[-1] - cl[0] if len(cl) > 1 else axes[0]
    a = chord / max(np.linalg.norm(chord), 1e-9)
    b = axes[1] if abs(axes[1] @ a) < 0.9 else axes[2]
    b = b - (b @ a) * a
    b /= np.linalg.norm(b)
    return np.stack([a, b, np.cross(a, b)])


def triplets(example_files, path, title: str = "") -> Path:
    """Fig. 5 for stored examples (``.npz`` from ``evaluate``): input; holes red; centerline red."""
    plt = _plt()
    files = sorted(example_files)
    fig = plt.figure(figsize=(12, 3.8 * len(files)))
    for r, f in enumerate(files):
        e = np.load(f)
        pts = e["partial_points"].astype(float)
        c = pts.mean(axis=0)
        rot = _side_view(pts, e["true_centerline"])

        def frame(x):
            x = np.asarray(x, float).reshape(-1, 3)
            return (x - c) @ rot.T

        p, v = frame(pts), frame(e["mesh_vertices"])
        faces, hole = e["mesh_faces"], e["hole_vertices"]
        hole_face = hole[faces].sum(axis=1) >= 2 if len(faces) else np.zeros(0, bool)
        label = f"{Path(f).stem.rpartition('-noise')[0]}\ntrue {float(e['true_coverage']):.1%}, " \
                f"estimated {float(e['coverage']):.1%}"
        ax = axes_3d(fig, (len(files), 3, 3 * r + 1), f"input cloud, {label}")
        ax.scatter(*p[::2].T, s=0.3, color="#555555")
        set_equal(ax, p)
        ax = axes_3d(fig, (len(files), 3, 3 * r + 2), "completed mesh, holes red")
        draw_surface(ax, v, faces[~hole_face], (0.78, 0.78, 0.8), 20000)
        draw_surface(ax, v, faces[hole_face], (0.9, 0.1, 0.1), 20000)
        set_equal(ax, p)  # the input cloud sets the scale of all three panels
        ax = axes_3d(fig, (len(files), 3, 3 * r + 3), "completed mesh, centerline red (GT black)")
        draw_surface(ax, v, faces, (0.8, 0.8, 0.82), 20000, alpha=0.25)
        gt, cl = frame(e["true_centerline"]), frame(e["centerline"])
        if len(gt):
            ax.plot(*gt.T, color="k", lw=1.2, ls="--")
        if len(cl):
            ax.plot(*cl.T, color="#d62728", lw=2)
        set_equal(ax, p)  # the input cloud sets the scale of all three panels
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return Path(path)


def all_figures(results: pd.DataFrame, tab: pd.DataFrame, run_dirs, out) -> list[Path]:
    """Box plots, scatter and, per method with stored examples, triplets at each noise level."""
    out = Path(out)
    paths = [boxplots(results, tab, out / "boxplots.png"), scatter(results, tab, out / "scatter.png")]
    for run in run_dirs:
        ex = Path(run) / "examples"
        if not ex.is_dir():
            continue
        for method_dir in sorted(p for p in ex.iterdir() if p.is_dir()):
            files = sorted(method_dir.glob("*.npz"))
            for noise in sorted({f.stem.rpartition("-noise")[2] for f in files}):
                chosen = [f for f in files if f.stem.endswith(f"-noise{noise}")]
                name = f"triplets-{method_dir.name}-noise{noise}.png"
                paths.append(triplets(chosen, out / name, f"{method_dir.name}, noise {noise} mm"))
    return paths
