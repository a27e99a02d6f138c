"""Decision 0156's session script: completion's estimate of every segment of a dataset at 0 and 0.5 mm, with the
true coverage and candidate signals of how sure the estimate is (all from the cloud and the estimate, none from the
truth), into a CSV.

    python interval_features.py DATA SPLIT OUT.csv [--limit N]
"""
import argparse
import sys
import time

import numpy as np
import pandas as pd
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from colonbench.baselines.threshold import threshold_coverage
from colonbench.baselines.unwrap import unwrap_coverage
from colonbench.benchmark.evaluate import noisy, select
from colonbench.completion.method import CompletionMethod, method_cloud
from colonbench.completion.surface import cloud_density, triangle_areas
from colonbench.errors import ColonbenchError
from colonbench.grid import even_subsample
from colonbench.shards.reader import Shard


def hole_patches(verts, faces, hole):
    """Area shares of the completed surface: in hole faces, in the largest connected hole patch."""
    area = triangle_areas(verts, faces)
    total = area.sum()
    hf = hole[faces].all(axis=1)
    if not hf.any() or total <= 0:
        return 0.0, 0.0, 0
    f = faces[hf]
    n = len(verts)
    rows = np.concatenate([f[:, 0], f[:, 1], f[:, 2]])
    cols = np.concatenate([f[:, 1], f[:, 2], f[:, 0]])
    g = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n))
    _, lab = connected_components(g, directed=False)
    fl = lab[f[:, 0]]
    per = np.bincount(fl, weights=area[hf])
    return float(area[hf].sum() / total), float(per.max() / total), int((per > 0.01 * total).sum())


def roughness(pts, k=12):
    """Median rms distance of points from their neighbours' local plane, mm (a noise proxy)."""
    sub = even_subsample(pts, 2000)
    tree = cKDTree(pts)
    _, idx = tree.query(sub, k=k)
    nb = pts[idx] - pts[idx].mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", nb, nb) / k
    ev = np.linalg.eigvalsh(cov)
    return float(np.median(np.sqrt(np.maximum(ev[:, 0], 0))))


def features(m, pts):
    est = m.estimate(pts)
    p = m.predictor(method_cloud(pts, m.thin_above))
    out = {"estimate": est.coverage, **{k: v for k, v in est.signals.items() if not isinstance(v, str)}}
    verts, faces, hole = est.mesh_vertices, np.asarray(est.mesh_faces), np.asarray(est.hole_vertices, bool)
    if len(faces):
        out["hole_share"], out["largest_hole"], out["hole_patches"] = hole_patches(verts, faces, hole)
        cl = est.centerline
        if len(cl) >= 2:
            d, _ = cKDTree(cl).query(verts)
            out["radius_mm"] = float(np.median(d))
            out["unwrap"] = unwrap_coverage(pts, cl).coverage
        out["area_mm2"] = float(triangle_areas(verts, faces).sum())
    out["threshold"] = threshold_coverage(p.heatmap, p.grid, pts, centerline_vox=p.centerline_vox).coverage
    out["voxel_mm"] = p.grid.voxel_size
    out["points"] = len(pts)
    out["density"] = cloud_density(pts)
    out["roughness_mm"] = roughness(pts)
    ext = pts - pts.mean(0)
    sv = np.linalg.svd(ext[:: max(1, len(ext) // 4000)], compute_uv=False)
    out["cloud_aspect"] = float(sv[1] / sv[0])
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("data")
    ap.add_argument("split")
    ap.add_argument("out")
    ap.add_argument("--limit", type=int, default=None)
    a = ap.parse_args()
    m = CompletionMethod()
    m.intervals = None
    _, picks = select(a.data, a.split)
    rows = []
    t0 = time.time()
    for name, indices in picks:
        with Shard(f"{a.data}/{name}") as sh:
            for i in indices[: a.limit]:
                geo = sh.geometry(i)
                for sigma in (0.0, 0.5):
                    pts = noisy(geo["partial_points"], sigma, 0, name, i)
                    base = {"shard": name, "index": i, "colon_id": geo["colon_id"], "noise_mm": sigma,
                            "hole_model": geo["hole_model"], "segment_mm": geo["length_mm"], "true": geo["coverage"]}
                    try:
                        rows.append({**base, **features(m, pts)})
                    except ColonbenchError as exc:
                        print(name, i, sigma, exc, file=sys.stderr)
        print(name, len(rows), f"{time.time() - t0:.0f}s", flush=True)
    pd.DataFrame(rows).to_csv(a.out, index=False)


if __name__ == "__main__":
    main()
