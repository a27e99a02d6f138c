"""Where completion's worst errors come from: each step swapped for its exact counterpart, one at a time.

    python scripts/attribute_tail.py --suites real-v1,wide-v1,video-v1 [--noise 0.5] [--share 0.1] [--data DIR]
                                     [--out attribution.csv]

For every suite, the worst ``--share`` of segments by completion's absolute coverage error (its shipped rows at
``--noise``) are estimated again with one step's output replaced by the truth:

- ``heatmap``: the exact target heatmap on the method's own grid (the network's output swapped);
- ``centerline``: the true centerline (voxels of the same grid) in place of the one found in the heatmap;
- ``planes``: the segment's true end planes (at the ends of its true centerline) in place of the ones found;
- ``holes``: a completed vertex is a hole where it lies nearer to the true hole points than to the partial cloud
  (the hole distance test swapped).

A swap *removes* a segment's error where it halves the absolute error; the segment is charged to the swap that
removes the most. Also recorded: the share of the segment's true length the cloud spans along the true centerline
(an unseen end). Prints the attribution table (share of the tail's segments and of its absolute error per step)
and writes one row per segment and variant.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.spatial import cKDTree

from colonbench.benchmark import shipped, suites
from colonbench.benchmark.evaluate import noisy
from colonbench.completion.heatmap_centerline import extract_centerline
from colonbench.completion.method import CompletionMethod, method_cloud
from colonbench.completion.planes import end_planes
from colonbench.completion.steps import complete
from colonbench.completion.surface import mesh_coverage
from colonbench.heatmaps import sample_heatmaps
from colonbench.polyline import arc_length
from colonbench.shards.reader import Shard

VARIANTS = ("base", "heatmap", "centerline", "planes", "holes")


def extent_share(points: np.ndarray, centerline: np.ndarray) -> float:
    """Share of the true centerline's length between the cloud's first and last projections onto it."""
    s = arc_length(centerline)
    _, nearest = cKDTree(centerline).query(points)
    return float((s[nearest].max() - s[nearest].min()) / max(s[-1], 1e-9))


def variants(method: CompletionMethod, pts: np.ndarray, geo: dict) -> dict:
    """Coverage of one segment with each step swapped for its exact counterpart."""
    cloud = method_cloud(pts, method.thin_above)
    p = method.predictor(cloud)
    grid, pred = p.grid, p.heatmap
    vox = grid.to_voxel(cloud)
    exact = sample_heatmaps(grid, cloud, geo["vertices"].astype(float), geo["faces"],
                            geo["centerline"].astype(float)).target
    true_cl = grid.to_voxel(geo["centerline"].astype(float))
    cl = p.centerline_vox
    steps = {"distance": method.hole_distance, "cut_rims": method.cut_rims, "shell_level": method.shell_level,
             "gaps": method.gaps}           # the method's own settings, as estimate() runs them
    out = {}
    base = complete(pred, cl, vox, **steps)
    out["base"] = base.coverage
    out["heatmap"] = complete(exact, extract_centerline(exact), vox, **steps).coverage
    out["centerline"] = complete(pred, true_cl, vox, **steps).coverage
    out["planes"] = complete(pred, cl, vox, **steps, planes=end_planes(true_cl)).coverage
    if len(base.vertices) and len(geo["hole_points"]):
        d_hole, _ = cKDTree(grid.to_voxel(geo["hole_points"].astype(float))).query(base.vertices)
        d_part, _ = cKDTree(vox).query(base.vertices)
        out["holes"] = mesh_coverage(base.vertices, base.faces, d_hole < d_part)
    else:
        out["holes"] = out["base"]
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--suites", default="real-v1,wide-v1,video-v1")
    ap.add_argument("--noise", type=float, default=0.5)
    ap.add_argument("--share", type=float, default=0.1)
    ap.add_argument("--data", help="suite data folder (default: colonbench's cache)")
    ap.add_argument("--out", default="attribution.csv")
    args = ap.parse_args()
    method = CompletionMethod()
    rows = []
    for suite in suites.parse(args.suites):
        if suite.task != "segments" or shipped.load(suite) is None:
            print(f"{suite.id}: skipped (whole colons, or no shipped results to take the tail from)")
            continue
        data = suites.ensure_data(suite, args.data, progress=False)
        ship = shipped.load(suite)[1]
        ship = ship[(ship["method"] == "completion") & (ship["noise_mm"] == args.noise)].copy()
        ship["abs"] = ship["coverage_error"].abs()
        tail = ship.nlargest(max(1, int(round(args.share * len(ship)))), "abs")
        for _, r in tail.iterrows():
            with Shard(Path(data) / r["shard"]) as shard:
                geo = shard.geometry(int(r["index"]))
            pts = noisy(geo["partial_points"], args.noise, suite.noise_seed, r["shard"], int(r["index"]))
            cov = variants(method, pts, geo)
            row = {"suite": suite.id, "shard": r["shard"], "index": int(r["index"]), "hole_model": r["hole_model"],
                   "true_coverage": r["true_coverage"], "shipped_error": r["coverage_error"],
                   "extent_share": extent_share(geo["partial_points"].astype(float), geo["centerline"].astype(float))}
            row.update({f"error_{k}": 100 * (v - r["true_coverage"]) for k, v in cov.items()})
            rows.append(row)
            print(suite.id, r["shard"], r["index"], {k: round(row[f"error_{k}"], 1) for k in cov}, flush=True)
    df = pd.DataFrame(rows)
    df.to_csv(args.out, index=False)
    base = df["error_base"].abs()
    gains = pd.DataFrame({k: base - df[f"error_{k}"].abs() for k in VARIANTS[1:]})
    best = gains.idxmax(axis=1).where(gains.max(axis=1) >= base / 2, "none")
    df["charged_to"] = best
    print(f"\n{len(df)} tail segments; base MAE {base.mean():.1f} points (recomputed; shipped "
          f"{df['shipped_error'].abs().mean() * 100:.1f}); bias {df['error_base'].mean():+.1f}")
    print("| step swapped | segments charged | share of the tail's error | tail MAE with the swap |")
    print("|---|---:|---:|---:|")
    for k in (*VARIANTS[1:], "none"):
        sel = df["charged_to"] == k
        mae = df[f"error_{k}"].abs().mean() if k != "none" else float("nan")
        print(f"| {k} | {sel.sum()} | {base[sel].sum() / base.sum():.0%} | {mae:.1f} |")
    short = df["extent_share"] < 0.9
    print(f"\ncloud spans < 90 % of the true length: {short.sum()} of {len(df)} tail segments "
          f"({base[short].sum() / base.sum():.0%} of the tail's error)")


if __name__ == "__main__":
    main()
