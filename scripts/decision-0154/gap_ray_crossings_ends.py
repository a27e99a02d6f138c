"""Where each gap ray of a complete segment (true >= 0.8, noiseless) crosses the true segment mesh."""
import sys
from pathlib import Path
import numpy as np, pandas as pd, trimesh
from scipy.spatial import cKDTree
sys.path.insert(0, str(Path(__file__).parent))
from gap_ray_kinds import gap_rays
from colonbench.benchmark.evaluate import noisy, select
from colonbench.completion.method import CompletionMethod, method_cloud
from colonbench.completion.planes import segment_planes
from colonbench.shards.reader import Shard
root, out = Path(sys.argv[1]), sys.argv[2]
m = CompletionMethod(); m.intervals = None
rows = []
for man in ("calibration-real",):
    data = root / man
    _, picks = select(data, "validation")
    for name, idx in picks:
        with Shard(data / name) as sh:
            for i in idx:
                geo = sh.geometry(i)
                if geo["coverage"] < 0.8:
                    continue
                cloud = method_cloud(noisy(geo["partial_points"], 0.0, 0, name, i), m.thin_above)
                pr = m.predictor(cloud); vox = pr.grid.to_voxel(cloud)
                planes = segment_planes(pr.centerline_vox, vox, True, pr.grid.voxel_size)
                res = gap_rays(pr.heatmap, pr.centerline_vox, planes)
                if res is None:
                    continue
                P, D, R = res[0], res[1], res[2]
                mesh = trimesh.Trimesh(pr.grid.to_voxel(geo["vertices"].astype(float)), geo["faces"], process=False)
                obs = np.zeros(len(geo["faces"]), bool); obs[geo["observed_faces"]] = True
                loc, ray, tri = mesh.ray.intersects_location(P, D, multiple_hits=True)
                dist = np.linalg.norm(loc.reshape(-1, 3) - P[ray], axis=1) if len(ray) else np.zeros(0)
                tree = cKDTree(vox)
                tc = pr.grid.to_voxel(geo["centerline"].astype(float))
                seglen = np.linalg.norm(np.diff(tc, axis=0), axis=1)
                s_at = np.concatenate([[0], np.cumsum(seglen)])
                nearest = cKDTree(tc).query(P)[1]
                t0 = (tc[1] - tc[0]) / np.linalg.norm(tc[1] - tc[0]); t1 = (tc[-1] - tc[-2]) / np.linalg.norm(tc[-1] - tc[-2])
                in0 = (P - tc[0]) @ t0; in1 = (tc[-1] - P) @ t1
                mt = cKDTree(mesh.vertices)
                pd_mesh = mt.query(P + R[:, None] * D)[0]
                for k in range(len(P)):
                    sel = np.nonzero(ray == k)[0]
                    if len(sel) == 0:
                        rows.append({"manifest": man, "seg": f"{name}:{i}", "true": geo["coverage"], "cross": "none", "in0": in0[k], "in1": in1[k], "L": s_at[-1], "R": R[k], "patch_mesh_d": pd_mesh[k],
                                     "ratio": np.nan, "cloud_d": np.nan}); continue
                    f = sel[np.argmin(dist[sel])]
                    rows.append({"manifest": man, "seg": f"{name}:{i}", "true": geo["coverage"],
                                 "cross": "observed" if obs[tri[f]] else "hole", "ratio": dist[f] / R[k],
                                 "cloud_d": tree.query(loc[f])[0], "in0": in0[k], "in1": in1[k], "L": s_at[-1], "R": R[k], "patch_mesh_d": pd_mesh[k]})
        print(man, name, len(rows), flush=True)
pd.DataFrame(rows).to_csv(out, index=False)
