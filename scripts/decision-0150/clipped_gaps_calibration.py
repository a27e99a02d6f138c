"""Decision 0150, rule 1: steps 10 and the candidate (gap patches clipped to the planes) from one prediction each."""
import sys
from pathlib import Path
import numpy as np, pandas as pd
sys.path.insert(0, "scripts")
from calibrate_intervals import NOISE_MM, MANIFESTS
from colonbench.benchmark.evaluate import noisy, select
from colonbench.completion.method import CompletionMethod, method_cloud
from colonbench.completion.steps import complete
from colonbench.shards.reader import Shard
root, out = Path(sys.argv[1]), sys.argv[2]
m = CompletionMethod(); m.intervals = None
rows = []
for man in MANIFESTS:
    data = root / man.stem
    _, picks = select(data, "validation")
    for name, idx in picks:
        with Shard(data / name) as sh:
            for i in idx:
                geo = sh.geometry(i)
                for sigma in NOISE_MM:
                    pts = method_cloud(noisy(geo["partial_points"], sigma, 0, name, i), m.thin_above)
                    p = m.predictor(pts)
                    vox = p.grid.to_voxel(pts)
                    r = {"manifest": man.stem, "shard": name, "index": i, "colon_id": geo["colon_id"], "noise_mm": sigma,
                         "hole_model": geo["hole_model"], "true": geo["coverage"]}
                    for tag, clip in (("c10", False), ("c11", True)):
                        r[tag] = complete(p.heatmap, p.centerline_vox, vox, voxel_mm=p.grid.voxel_size, clip_gaps=clip).coverage
                    rows.append(r)
        print(man.stem, name, len(rows), flush=True)
pd.DataFrame(rows).to_csv(out, index=False)
