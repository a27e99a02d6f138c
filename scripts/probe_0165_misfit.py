"""Decision record 0165's probe: does the completed wall's distance to the cloud tell paper-like colons from
widened and real ones, and their sphere-hole segments apart?"""
import sys
from pathlib import Path
import numpy as np, pandas as pd
from scipy.spatial import cKDTree
from colonbench.benchmark.evaluate import select
from colonbench.completion.method import CompletionMethod, method_cloud
from colonbench.shards.reader import Shard

method = CompletionMethod(None)
method.intervals = None
rows = []
for m, step in (("calibration", 3), ("calibration-paper", 1), ("validation-real", 4)):
    data = Path("data") / m
    _, picks = select(data, "validation")
    k = 0
    for name, indices in picks:
        with Shard(data / name) as shard:
            for i in indices:
                k += 1
                if k % step:
                    continue
                geo = shard.geometry(i)
                pts = method_cloud(geo["partial_points"])
                est = method.estimate(geo["partial_points"])
                v = est.mesh_vertices
                if not len(v):
                    continue
                d_cloud = cKDTree(v).query(pts)[0]                    # cloud -> completed wall
                seen = np.ones(len(v), bool); seen[est.hole_vertices] = False
                d_wall = cKDTree(pts).query(v[seen])[0] if seen.any() else np.zeros(1)   # seen wall -> cloud
                rows.append({"m": m, "colon": geo["colon_id"], "hole_model": geo["hole_model"],
                             "true": geo["coverage"], "estimate": est.coverage,
                             "c50": np.percentile(d_cloud, 50), "c90": np.percentile(d_cloud, 90),
                             "far2": float((d_cloud > 2).mean()), "far4": float((d_cloud > 4).mean()),
                             "w50": np.percentile(d_wall, 50), "w90": np.percentile(d_wall, 90)})
    print(m, len(rows), flush=True)
df = pd.DataFrame(rows)
df.to_csv("/tmp/probe/misfit.csv", index=False)
