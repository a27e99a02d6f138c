"""Decision 0154: per gap ray of the calibration set (noiseless), did it meet a wall (far) or none, and is it at a
true hole. `python gap_ray_kinds.py DATA OUT.csv`, DATA holding calibration/ and calibration-real/."""
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
from colonbench.shards.reader import Shard

def gap_rays(heatmap, cl, planes, valley=G.GAP_VALLEY):
    p, t, u, v = G._station_frames(cl, planes, END_INSET, heatmap)
    if len(p) == 0:
        return None
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
    if not met.any():
        return None
    enough = met.sum(axis=1) >= G.GAP_MIN_HITS * rays
    radius = np.full(len(p), float(np.median(first[met])))
    radius[enough] = [np.median(f[np.isfinite(f)]) for f in first[enough]]
    gap = (~met | (first > G.GAP_FAR * radius[:, None])) & faint
    i, j = np.nonzero(gap)
    # neighbours' hit ratio (rays j-1, j+1) to see ellipse-like continuity
    nb = np.stack([first[i, (j - 1) % rays], first[i, (j + 1) % rays]], 1) / radius[i, None]
    return p[i], d[i, j], radius[i], met[i, j], first[i, j] / radius[i], nb, enough[i], len(p)

if __name__ == "__main__":
    root, out = Path(sys.argv[1]), sys.argv[2]
    m = CompletionMethod(); m.intervals = None
    rows, segs = [], []
    for man in ("calibration-real", "calibration"):
        data = root / man
        _, picks = select(data, "validation")
        for name, idx in picks:
            with Shard(data / name) as sh:
                for i in idx:
                    geo = sh.geometry(i)
                    cloud = method_cloud(noisy(geo["partial_points"], 0.0, 0, name, i), m.thin_above)
                    pr = m.predictor(cloud); vox = pr.grid.to_voxel(cloud)
                    planes = segment_planes(pr.centerline_vox, vox, True, pr.grid.voxel_size)
                    res = gap_rays(pr.heatmap, pr.centerline_vox, planes)
                    segs.append({"manifest": man, "shard": name, "index": i, "true": geo["coverage"],
                                 "hole_model": geo["hole_model"], "rays": 0 if res is None else len(res[0]),
                                 "stations": 0 if res is None else res[7]})
                    if res is None:
                        continue
                    P, D, R, MET, RATIO, NB, EN, _ = res
                    hp = geo["hole_points"]; tree = cKDTree(vox)
                    th = cKDTree(pr.grid.to_voxel(hp.astype(float))) if len(hp) else None
                    q = P + R[:, None] * D
                    dc = tree.query(q)[0]
                    dh = th.query(q)[0] if th is not None else np.full(len(q), np.inf)
                    for k in range(len(P)):
                        rows.append({"manifest": man, "shard": name, "index": i, "true": geo["coverage"],
                                     "hole_model": geo["hole_model"], "met": bool(MET[k]), "ratio": RATIO[k],
                                     "nb0": NB[k, 0], "nb1": NB[k, 1], "enough": bool(EN[k]), "radius": R[k],
                                     "true_hole": bool(dh[k] < dc[k])})
            print(man, name, len(rows), flush=True)
    pd.DataFrame(rows).to_csv(out, index=False)
    pd.DataFrame(segs).to_csv(out.replace(".csv", "-segs.csv"), index=False)
