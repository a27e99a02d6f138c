import sys
from pathlib import Path
import numpy as np, pandas as pd
from scipy.spatial import cKDTree
from colonbench.benchmark.evaluate import noisy, select
from colonbench.completion.method import CompletionMethod, method_cloud
from colonbench.completion.planes import segment_planes, inside_planes
from colonbench.completion.gaps import wall_gaps
from colonbench.completion.surface import hole_vertices
from colonbench.heatmaps import sample_heatmaps
from colonbench.completion.heatmap_centerline import extract_centerline
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
            for sigma in (0.0,):
                cloud = method_cloud(noisy(geo["partial_points"], sigma, 0, name, i), m.thin_above)
                p = m.predictor(cloud); vox = p.grid.to_voxel(cloud)
                exact = sample_heatmaps(p.grid, cloud, geo["vertices"].astype(float), geo["faces"], geo["centerline"].astype(float)).target
                for tag, hm, cl in (("net", p.heatmap, p.centerline_vox), ("gt", exact, extract_centerline(exact))):
                    planes = segment_planes(cl, vox, True, p.grid.voxel_size)
                    gv, gf = wall_gaps(hm, cl, planes)
                    if len(gf) == 0:
                        rows.append({"shard": name, "index": i, "true": geo["coverage"], "hole_model": geo["hole_model"], "tag": tag, "gap_area": 0.0, "outside": 0.0, "near_cloud": 0.0, "near_truth_hole": 0.0}); continue
                    quads = gv.reshape(-1, 4, 3); centre = quads.mean(axis=1)
                    area = triangle_areas(gv, gf).reshape(2, -1).sum(axis=0)
                    outside = ~inside_planes(gv, planes).reshape(-1, 4).all(axis=1)
                    near = ~hole_vertices(centre, vox)
                    # near a true hole point?
                    hp = geo.get("hole_points")
                    nth = np.zeros(len(centre), bool)
                    if hp is not None and len(hp):
                        d, _ = cKDTree(p.grid.to_voxel(hp)).query(centre); dc, _ = cKDTree(vox).query(centre)
                        nth = d < dc
                    rows.append({"shard": name, "index": i, "true": geo["coverage"], "hole_model": geo["hole_model"], "tag": tag,
                                 "gap_area": area.sum(), "outside": area[outside].sum(), "near_cloud": area[near].sum(), "near_truth_hole": area[nth].sum()})
    print(name, len(rows), flush=True)
pd.DataFrame(rows).to_csv(out, index=False)
