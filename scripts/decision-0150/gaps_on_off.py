"""Decision 0150: real complete segments estimated with and without the wall gaps (net and exact heatmap).

    python scripts/decision-0150/gaps_on_off.py DATA SPLIT OUT.csv
"""
import sys
from pathlib import Path
import numpy as np, pandas as pd
from colonbench.benchmark.evaluate import noisy, select
from colonbench.completion.method import CompletionMethod, method_cloud
from colonbench.completion.steps import complete
from colonbench.completion.surface import mesh_coverage
from colonbench.heatmaps import sample_heatmaps
from colonbench.meshes import triangle_areas
from colonbench.shards.reader import Shard

data, split, out = Path(sys.argv[1]), sys.argv[2], sys.argv[3]
m = CompletionMethod(); m.intervals = None
_, picks = select(data, split)
rows = []
for name, idx in picks:
    with Shard(data / name) as sh:
        for i in idx:
            geo = sh.geometry(i)
            if geo["coverage"] < 0.8:
                continue
            for sigma in (0.0, 0.5):
                cloud = method_cloud(noisy(geo["partial_points"], sigma, 0, name, i), m.thin_above)
                p = m.predictor(cloud)
                vox = p.grid.to_voxel(cloud)
                r = {"shard": name, "index": i, "colon_id": geo["colon_id"], "hole_model": geo["hole_model"], "noise": sigma, "true": geo["coverage"]}
                exact = sample_heatmaps(p.grid, cloud, geo["vertices"].astype(float), geo["faces"], geo["centerline"].astype(float)).target
                for tag, hm, cl in (("net", p.heatmap, p.centerline_vox), ("gt", exact, None)):
                    if cl is None:
                        from colonbench.completion.heatmap_centerline import extract_centerline
                        cl = extract_centerline(hm)
                    c = complete(hm, cl, vox)
                    nmesh = len(c.vertices) - int(c.hole.size - 0)  # placeholder
                    area = triangle_areas(c.vertices, c.faces)
                    fh = c.hole[c.faces].all(axis=1)
                    c0 = complete(hm, cl, vox, gaps=False)
                    r[f"{tag}"] = c.coverage; r[f"{tag}_nogaps"] = c0.coverage
                    r[f"{tag}_area"] = float(area.sum()); r[f"{tag}_area_nogaps"] = float(triangle_areas(c0.vertices, c0.faces).sum())
                rows.append(r)
    print(name, len(rows), flush=True)
pd.DataFrame(rows).to_csv(out, index=False)
