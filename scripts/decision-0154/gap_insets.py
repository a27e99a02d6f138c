"""Decision 0154, rule 1: steps 10 and the candidates (gap stations k voxels inside the planes), one prediction each."""
import functools
import sys
from pathlib import Path
import numpy as np, pandas as pd
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from calibrate_intervals import NOISE_MM
from colonbench.benchmark.evaluate import noisy, select
from colonbench.completion import steps as S
from colonbench.completion.gaps import wall_gaps
from colonbench.completion.method import CompletionMethod, method_cloud
from colonbench.shards.reader import Shard
root, man, out = Path(sys.argv[1]), sys.argv[2], sys.argv[3]
m = CompletionMethod(); m.intervals = None
rows = []
data = root / man
_, picks = select(data, "validation")
for name, idx in picks:
    with Shard(data / name) as sh:
        for i in idx:
            geo = sh.geometry(i)
            for sigma in NOISE_MM:
                pts = method_cloud(noisy(geo["partial_points"], sigma, 0, name, i), m.thin_above)
                p = m.predictor(pts)
                vox = p.grid.to_voxel(pts)
                r = {"manifest": man, "shard": name, "index": i, "colon_id": geo["colon_id"], "noise_mm": sigma,
                     "hole_model": geo["hole_model"], "true": geo["coverage"]}
                for k in (1, 2, 3, 4, 6):
                    S.wall_gaps = functools.partial(wall_gaps, inset=float(k))
                    r[f"k{k}"] = S.complete(p.heatmap, p.centerline_vox, vox, voxel_mm=p.grid.voxel_size).coverage
                rows.append(r)
    print(man, name, len(rows), flush=True)
pd.DataFrame(rows).to_csv(out, index=False)
