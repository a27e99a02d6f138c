# Decision record 0173's one-off look (Afterwards), run from the repository root while the signals5 caches of
# scripts/calibrate_intervals.py at d53f13a existed; removed after.
import sys
from pathlib import Path
import numpy as np, pandas as pd
from scipy.spatial import cKDTree
import colonbench.completion.method as M
from colonbench.completion.method import CompletionMethod
from colonbench.shards.reader import Shard
from colonbench.polyline import resample
cap = {}
_fh = M.from_heatmap
def fh(heatmap, grid, points, *a, **k):
    est = _fh(heatmap, grid, points, *a, **k)
    cap["points"] = np.asarray(points, float)
    return est
M.from_heatmap = fh
ds, n = sys.argv[1], int(sys.argv[2])
d = pd.read_csv(f"data/{ds}/completion-estimates-6d813b3c4351-steps=10-signals5.csv")
d = d[d.noise_mm == 0]; d = d.sample(min(n, len(d)), random_state=1)
m = CompletionMethod(None); m.intervals = None
rows = []
for _, r in d.iterrows():
    with Shard(Path("data") / ds / r.shard) as s:
        g = s.geometry(int(r["index"]))
    est = m.estimate(g["partial_points"])
    v, f = est.mesh_vertices, est.mesh_faces
    area = 0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1).sum() if len(f) else 0.0
    cl = resample(np.asarray(est.centerline, float), 0.25) if len(est.centerline) > 1 else None
    if cl is None:
        continue
    s_ = np.r_[0, np.cumsum(np.linalg.norm(np.diff(cl, axis=0), axis=1))]
    dist, idx = cKDTree(cl).query(v)
    interior = (s_[idx] > 2.0) & (s_[idx] < s_[-1] - 2.0)
    r_loc = np.median(dist[interior]) if interior.sum() > 20 else np.median(dist)
    rows.append(dict(colon=r.colon_id, end=r.hole_model.endswith("+end"), L=r.segment_mm, true=r.true, est=est.coverage,
                     span=r.span_mm, surf=area / (2 * np.pi * r_loc), r_loc=r_loc, radius=r.radius_mm))
o = pd.DataFrame(rows); o.to_csv(f"/tmp/surf-{ds}.csv", index=False)
