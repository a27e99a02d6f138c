"""Decision 0155: per calibration estimate, the unscaled estimate, the line between the planes and the span to
the planes (mm). `python span.py DATA MANIFEST OUT.csv`."""
import sys
from pathlib import Path
import numpy as np, pandas as pd
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from calibrate_intervals import NOISE_MM
from colonbench.benchmark.evaluate import noisy, select
from colonbench.completion.gaps import reach_planes
from colonbench.completion.method import CENTERLINE_SPACING_MM, CompletionMethod, method_cloud
from colonbench.completion.steps import complete
from colonbench.polyline import resample
from colonbench.completion.planes import line_between
from colonbench.polyline import arc_length
from colonbench.shards.reader import Shard
root, man, out = Path(sys.argv[1]), sys.argv[2], sys.argv[3]
split = sys.argv[4] if len(sys.argv) > 4 else "validation"
m = CompletionMethod(); m.intervals = None
rows = []
data = root / man
_, picks = select(data, split)
for name, idx in picks:
    with Shard(data / name) as sh:
        for i in idx:
            geo = sh.geometry(i)
            for sigma in NOISE_MM:
                raw = noisy(geo["partial_points"], sigma, 0, name, i)
                pts = method_cloud(raw, m.thin_above)
                p = m.predictor(pts)
                comp = complete(p.heatmap, p.centerline_vox, p.grid.to_voxel(pts), voxel_mm=p.grid.voxel_size)
                inside = line_between(p.centerline_vox, comp.planes)
                span = reach_planes(inside, comp.planes)
                vs = p.grid.voxel_size
                rows.append({"manifest": man, "shard": name, "index": i, "colon_id": geo["colon_id"],
                             "noise_mm": sigma, "hole_model": geo["hole_model"], "segment_mm": geo["length_mm"],
                             "true": geo["coverage"], "estimate": comp.coverage,
                             "length_mm": round(float(arc_length(resample(p.grid.to_mm(inside), CENTERLINE_SPACING_MM))[-1]), 2),
                             "line_mm": float(arc_length(inside)[-1]) * vs, "span_mm": float(arc_length(span)[-1]) * vs,
                             "rims": comp.rims})
    print(man, name, len(rows), flush=True)
pd.DataFrame(rows).to_csv(out, index=False)
