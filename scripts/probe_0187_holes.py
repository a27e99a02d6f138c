"""Decision record 0187's measurement (a one-off probe, removed after it): the holes' shape in the unwrapped cloud,
screened for the paper-like colons' sphere-hole estimates. Run from the repository root with the calibration's
datasets in data/:

    python scripts/probe_0187_holes.py make PART PARTS     (every calibrated estimate made again; PART 0 and 1)
    python scripts/probe_0187_holes.py screen
"""
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import torch
from scipy import ndimage
from scipy.stats import mannwhitneyu
from skimage.measure import regionprops

sys.path.insert(0, str(Path(__file__).resolve().parent))
import calibrate_intervals as ci                                          # noqa: E402
from colonbench.baselines.unwrap import CELL_MM, MORPH_CELLS, _disk, unwrap   # noqa: E402
from colonbench.benchmark.evaluate import noisy                           # noqa: E402
from colonbench.completion import caltable                                # noqa: E402
from colonbench.completion.method import CompletionMethod, method_cloud, model_path, steps_version   # noqa: E402
from colonbench.shards.reader import Shard                                 # noqa: E402

NAMES = ("hole_solidity", "hole_elongation", "inner_share")
CACHE = Path("runs/probe-0187")


def table():
    path = model_path(None)
    df = ci.with_units(ci.with_sets(caltable.read(caltable.path_for(path, steps_version()), ci.SIGNALS,
                                                  ci.table_source(path))))
    return df[df["set"].isin(ci.CALIBRATED)].reset_index(drop=True)


def hole_shape(points, line):
    """The three signals of a cloud (mm) around its line (mm), as the record defines them."""
    if len(line) < 2:
        return {"hole_solidity": 1.0, "hole_elongation": 0.0, "inner_share": 0.0}
    s, theta, radius, ln, _, sample = unwrap(points, line, index=True)
    n_rows = max(int(np.ceil(ln.length / CELL_MM)), 1)
    n_cols = max(int(np.round(2 * np.pi * float(np.mean(radius)) / CELL_MM)), 4)
    row = np.minimum(sample * n_rows // max(len(ln.points) - 1, 1), n_rows - 1)
    col = np.clip((theta / (2 * np.pi) * n_cols).astype(int), 0, n_cols - 1)
    occ = np.zeros((n_rows, n_cols), bool)
    occ[row, col] = True
    disk, pad = _disk(MORPH_CELLS), MORPH_CELLS
    w = np.pad(np.pad(occ, ((0, 0), (2 * pad, 2 * pad)), mode="wrap"), ((2 * pad, 2 * pad), (0, 0)), mode="edge")
    occ = ndimage.binary_opening(ndimage.binary_closing(w, disk), disk)[2 * pad:-2 * pad, 2 * pad:-2 * pad]
    empty = ~occ
    empty = np.roll(empty, -int(np.argmin(empty.sum(axis=0))), axis=1)    # cut the angle where least is empty
    labels, n = ndimage.label(empty)
    ends = set(np.unique(labels[0])) | set(np.unique(labels[-1]))
    props = [p for p in regionprops(labels) if p.label not in ends and p.area >= 4]
    inner = sum(p.area for p in props)
    if not props:
        return {"hole_solidity": 1.0, "hole_elongation": 0.0, "inner_share": 0.0}
    a = np.array([p.area for p in props], float)
    return {"hole_solidity": float((a * [p.solidity for p in props]).sum() / a.sum()),
            "hole_elongation": float((a * [p.eccentricity for p in props]).sum() / a.sum()),
            "inner_share": float(inner / max(empty.sum(), 1))}


def make(part, parts):
    torch.set_num_threads(1)
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
                            "noise_mm": float(r["noise_mm"]), **hole_shape(method_cloud(pts), est.centerline)})
        print(manifest, shard, len(out), flush=True)
    CACHE.mkdir(parents=True, exist_ok=True)
    pd.DataFrame(out).to_csv(CACHE / f"{part}-of-{parts}.csv", index=False)


def screen():
    cal = table().merge(pd.concat([pd.read_csv(p) for p in sorted(CACHE.glob("*.csv"))]),
                        on=["manifest", "shard", "index", "noise_mm"], how="inner", validate="one_to_one")
    label = ((cal["set"] == "V_paper") & (cal["hole_model"] == "spheres")).to_numpy()
    print(f"{len(cal)} calibrated estimates, {label.sum()} of V_paper's sphere holes")
    for n in NAMES:
        aucs = []
        for sigma in sorted(cal["noise_mm"].unique()):
            m = (cal["noise_mm"] == sigma).to_numpy()
            y, x = label[m], cal.loc[m, n].to_numpy()
            a = mannwhitneyu(x[y], x[~y]).statistic / (y.sum() * (~y).sum())
            aucs.append(round(float(max(a, 1 - a)), 3))
        med = cal.groupby(["set", "hole_model"])[n].median().round(3)
        print(f"  {n}: AUC by noise {aucs}; medians {med.to_dict()}")


if __name__ == "__main__":
    if sys.argv[1] == "make":
        make(int(sys.argv[2]), int(sys.argv[3]))
    else:
        screen()
