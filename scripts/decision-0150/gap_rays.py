"""Per gap ray: does it pass the cloud? (decision 0150's lead)"""
import sys
from pathlib import Path
import numpy as np, pandas as pd
from scipy import ndimage
from scipy.spatial import cKDTree
from colonbench.benchmark.evaluate import noisy, select
from colonbench.completion import gaps as G
from colonbench.completion.method import CompletionMethod, method_cloud
from colonbench.completion.planes import segment_planes, END_INSET
from colonbench.completion.surface import SURFACE_THRESHOLD
from colonbench.heatmaps import sample_heatmaps
from colonbench.shards.reader import Shard

def gap_rays(heatmap, cl, planes, valley=G.GAP_VALLEY):
    p, t, u, v = G._station_frames(cl, planes, END_INSET, heatmap)
    size = heatmap.shape[0]; rays = G.GAP_RAYS
    theta = np.arange(rays) * 2 * np.pi / rays
    d = np.cos(theta)[None, :, None] * u[:, None] + np.sin(theta)[None, :, None] * v[:, None]
    r = np.arange(G.GAP_STEP, float(size), G.GAP_STEP)
    wall = ndimage.binary_dilation(heatmap < SURFACE_THRESHOLD).ravel()
    with np.errstate(divide="ignore", invalid="ignore"):
        exits = np.where(d > 0, (size - 0.5 - p[:, None]) / d, np.where(d < 0, (-0.5 - p[:, None]) / d, np.inf))
    exit_r = exits.min(axis=-1)
    x = np.rint(p[:, None, None] + d[:, :, None] * r[None, None, :, None]).astype(np.int64)
    np.clip(x, 0, size - 1, out=x)
    flat = (x[..., 0] * size + x[..., 1]) * size + x[..., 2]
    within = r < exit_r[..., None]
    hit = wall[flat] & within
    first = np.where(hit.any(axis=-1), r[hit.argmax(axis=-1)] + G.GAP_GROWN, np.inf)
    faint = np.where(within, heatmap.ravel()[flat], np.inf).min(axis=-1) < valley
    met = np.isfinite(first)
    enough = met.sum(axis=1) >= G.GAP_MIN_HITS * rays
    radius = np.full(len(p), float(np.median(first[met])))
    radius[enough] = [np.median(f[np.isfinite(f)]) for f in first[enough]]
    gap = (~met | (first > G.GAP_FAR * radius[:, None])) & faint
    i, j = np.nonzero(gap)
    return p[i], d[i, j], radius[i], exit_r[i, j]

data, split, out = Path(sys.argv[1]), sys.argv[2], sys.argv[3]
m = CompletionMethod(); m.intervals = None
_, picks = select(data, split)
rows = []
for name, idx in picks:
    with Shard(data / name) as sh:
        for i in idx:
            geo = sh.geometry(i)
            cloud = method_cloud(noisy(geo["partial_points"], 0.0, 0, name, i), m.thin_above)
            pr = m.predictor(cloud); vox = pr.grid.to_voxel(cloud)
            planes = segment_planes(pr.centerline_vox, vox, True, pr.grid.voxel_size)
            P, D, R, E = gap_rays(pr.heatmap, pr.centerline_vox, planes)
            hp = geo["hole_points"]; tree = cKDTree(vox)
            th = cKDTree(pr.grid.to_voxel(hp.astype(float))) if len(hp) else None
            for k in range(len(P)):
                # cloud points within 1.5 voxels of the ray, beyond 0.3 of the median radius
                s = np.arange(0.3 * R[k], min(E[k], 4 * R[k]), 0.5)
                pts = P[k] + s[:, None] * D[k]
                dd, _ = tree.query(pts)
                passes = bool((dd <= 1.5).any())
                at = float(s[np.argmax(dd <= 1.5)] / R[k]) if passes else np.nan
                q = P[k] + R[k] * D[k]
                true_hole = bool(th is not None and th.query(q)[0] < tree.query(q)[0])
                rows.append({"shard": name, "index": i, "true": geo["coverage"], "hole_model": geo["hole_model"], "passes": passes, "at": at, "true_hole": true_hole, "radius": R[k]})
    print(name, len(rows), flush=True)
pd.DataFrame(rows).to_csv(out, index=False)
