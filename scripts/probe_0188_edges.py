"""Decision record 0188's measurement (a one-off probe, removed after it): where the cloud's hole edges lie against
the wall (`edge_inset`, `crest_share`, `edge_bend`), screened for the paper-like colons' sphere-hole estimates (A) and
for the far-off estimates of the real validation colons where both ends were seen (B). Run from the repository root
with the calibration's datasets in data/:

    python scripts/probe_0188_edges.py make PART PARTS     (every calibrated estimate made again; PART 0 and 1)
    python scripts/probe_0188_edges.py screen
"""
import sys
from pathlib import Path

import numpy as np
import open3d as o3d
import pandas as pd
import torch
from scipy.spatial import cKDTree
from scipy.stats import mannwhitneyu

sys.path.insert(0, str(Path(__file__).resolve().parent))
import calibrate_intervals as ci                                          # noqa: E402
from colonbench.benchmark.evaluate import noisy                           # noqa: E402
from colonbench.completion import caltable                                # noqa: E402
from colonbench.completion.method import CompletionMethod, method_cloud, model_path, steps_version   # noqa: E402
from colonbench.shards.reader import Shard                                 # noqa: E402

NAMES = ("edge_inset", "crest_share", "edge_bend")
CACHE = Path("runs/probe-0188")
RADIUS, MAX_NN, END_MM, LOCAL_MM, CREST, MIN_EDGE = 3.0, 30, 5.0, 5.0, 0.85, 10


def table():
    path = model_path(None)
    df = ci.with_units(ci.with_sets(caltable.read(caltable.path_for(path, steps_version()), ci.SIGNALS,
                                                  ci.table_source(path))))
    return df[df["set"].isin(ci.CALIBRATED)].reset_index(drop=True)


def variation(pts, tree, idx):
    """Surface variation lambda_min / sum(lambda) of the RADIUS neighbourhood of the points idx."""
    out = np.full(len(idx), np.nan)
    for k, nb in enumerate(tree.query_ball_point(pts[idx], RADIUS)):
        if len(nb) >= 5:
            lam = np.linalg.eigvalsh(np.cov(pts[nb].T))
            out[k] = lam[0] / max(lam.sum(), 1e-12)
    return out


def edges(points, line):
    """The three signals of a cloud (points, (n, 3) mm) around its line ((m, 3) mm), as the record defines them."""
    none = {"edge_inset": 1.0, "crest_share": 0.0, "edge_bend": 1.0, "n_edge": 0}
    pts = np.asarray(points, float)
    if len(line) < 2 or len(pts) < 50:
        return none
    line = np.asarray(line, float)
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(line, axis=0), axis=1))])
    r, j = cKDTree(line).query(pts)
    t = arc[j]
    pc = o3d.t.geometry.PointCloud(o3d.core.Tensor(pts, o3d.core.float64))
    pc.estimate_normals(max_nn=MAX_NN, radius=RADIUS)
    _, mask = pc.compute_boundary_points(RADIUS, MAX_NN, 90.0)
    edge = mask.numpy().astype(bool) & (t > arc[0] + END_MM) & (t < arc[-1] - END_MM)
    b = np.flatnonzero(edge)
    if len(b) < MIN_EDGE:
        return {**none, "n_edge": int(len(b))}
    order = np.argsort(t)
    ts, rs = t[order], r[order]
    lo = np.searchsorted(ts, t[b] - LOCAL_MM)
    hi = np.searchsorted(ts, t[b] + LOCAL_MM, side="right")
    r_loc = np.array([np.median(rs[a:z]) for a, z in zip(lo, hi)])
    ratio = r[b] / np.maximum(r_loc, 1e-6)
    tree = cKDTree(pts)
    every = np.linspace(0, len(pts) - 1, min(len(pts), 2000)).astype(int)
    bend = np.nanmedian(variation(pts, tree, b)) / max(np.nanmedian(variation(pts, tree, every)), 1e-12)
    return {"edge_inset": float(np.median(ratio)), "crest_share": float(np.mean(ratio < CREST)),
            "edge_bend": float(bend), "n_edge": int(len(b))}


def make(part, parts):
    torch.set_num_threads(1)
    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    cal = table()
    method = CompletionMethod(None)
    method.intervals = None
    keys = sorted(set(zip(cal["manifest"], cal["shard"])))[part::parts]
    out = []
    for manifest, shard in keys:
        g = cal[(cal["manifest"] == manifest) & (cal["shard"] == shard)]
        with Shard(Path("data") / manifest / shard) as s:
            for _, r in g.iterrows():
                pts = noisy(s.geometry(int(r["index"]))["partial_points"], float(r["noise_mm"]), 0, shard,
                            int(r["index"]))
                est = method.estimate(pts)
                if abs(est.coverage - r["estimate"]) > 1e-6:
                    raise SystemExit(f"{manifest} {shard} {r['index']}: {est.coverage} is not {r['estimate']}")
                out.append({"manifest": manifest, "shard": shard, "index": int(r["index"]),
                            "noise_mm": float(r["noise_mm"]), **edges(method_cloud(pts), est.centerline)})
        print(manifest, shard, len(out), flush=True)
    CACHE.mkdir(parents=True, exist_ok=True)
    pd.DataFrame(out).to_csv(CACHE / f"{part}-of-{parts}.csv", index=False)


def auc(y, x):
    a = mannwhitneyu(x[y], x[~y]).statistic / (y.sum() * (~y).sum())
    return round(float(max(a, 1 - a)), 3)


def screen():
    cal = table().merge(pd.concat([pd.read_csv(p) for p in sorted(CACHE.glob("*.csv"))]),
                        on=["manifest", "shard", "index", "noise_mm"], how="inner", validate="one_to_one")
    sphere = ((cal["set"] == "V_paper") & (cal["hole_model"] == "spheres")).to_numpy()
    paper = (cal["set"] == "V_paper").to_numpy()
    camera = paper & (cal["hole_model"] == "camera").to_numpy()
    print(f"{len(cal)} calibrated estimates, {sphere.sum()} of V_paper's sphere holes; "
          f"edge points: median {cal['n_edge'].median():.0f}, none {int((cal['n_edge'] < MIN_EDGE).sum())}")
    print("A: V_paper's sphere holes against all others, per noise level (within V_paper: against its camera holes)")
    for n in NAMES:
        all_, within = [], []
        for sigma in sorted(cal["noise_mm"].unique()):
            m = (cal["noise_mm"] == sigma).to_numpy()
            all_.append(auc(sphere[m], cal.loc[m, n].to_numpy()))
            w = m & (sphere | camera)
            within.append(auc(sphere[w], cal.loc[w, n].to_numpy()))
        med = cal.groupby(["set", "hole_model"])[n].median().round(3)
        print(f"  {n}: AUC {all_} (within V_paper {within}); medians {med.to_dict()}")
    real = cal[(cal["set"] == "V_real") & ~cal["hole_model"].str.endswith("+end")].reset_index(drop=True)
    far = ((real["true"] - real["estimate"]).abs() > ci.BIG).to_numpy()
    print(f"B: {len(real)} estimates without an erased end on the real validation colons, {far.sum()} far off")
    for n in NAMES:
        aucs = {}
        for colon in sorted(real["cell"].unique()):
            c = (real["cell"] == colon).to_numpy()
            aucs[colon] = auc(far[c], real.loc[c, n].to_numpy())
        x = real[n].to_numpy()
        print(f"  {n}: AUC {aucs}; median far / not {np.median(x[far]):.3f} / {np.median(x[~far]):.3f}")


if __name__ == "__main__":
    if sys.argv[1] == "make":
        make(int(sys.argv[2]), int(sys.argv[3]))
    else:
        screen()
