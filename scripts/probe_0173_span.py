"""Decision record 0173's one-off probe (removed after): with a length given, scale the coverage by the share of the
segment the cloud spans, counting the cloud the planes clip away. For a sample of cached estimates (at 0 mm), run
the method again, take the share of the cloud's points inside its planes, and compare the known-length MAE of
``coverage * span / length`` (shipped, where under 0.9) with ``coverage * span / length / inside share`` (where
that is under 0.9). Run from the repository root after scripts/calibrate_intervals.py has cached its estimates:
``python scripts/probe_0173_span.py DATASET N``. The rule's measurement, after the calibration script has made its
estimates again with ``inside_share``: ``python scripts/probe_0173_span.py --measure``."""
import sys
from pathlib import Path

import numpy as np
import pandas as pd

import colonbench.completion.method as M
from colonbench.completion.method import CompletionMethod
from colonbench.completion.planes import inside_planes
from colonbench.shards.reader import Shard


def measure():
    """The rule's measurement: the no-length estimates against the cache before (identical?), and each set's
    known-length MAE with the shipped scaling and with the change, both noise levels pooled."""
    tag = "completion-estimates-6d813b3c4351-steps=10-signals"
    sets = {"calibration": "V_wide", "calibration-paper": "V_paper", "calibration-paper-more": "V_paper",
            "validation-real": "V_real", "calibration-real": "train_real"}
    parts = []
    for ds, name in sets.items():
        new = pd.read_csv(f"data/{ds}/{tag}5.csv")
        old = pd.read_csv(f"data/{ds}/{tag}4.csv")
        cols = [c for c in old.columns if c in new.columns]
        same = old[cols].equals(new[cols])
        print(f"{ds}: {len(new)} estimates; no-length estimates and signals identical to the cache before: {same}")
        if not same:
            diff = (old[cols] != new[cols]) & ~(old[cols].isna() & new[cols].isna())
            print("  columns that differ:", diff.sum()[diff.sum() > 0].to_dict())
        parts.append(new.assign(set=name))
    df = pd.concat(parts, ignore_index=True)
    df.loc[(df.set == "V_wide") & (df.colon_id >= 900000), "set"] = "train_real"
    df["cell"] = np.where(df.set == "V_real", df.colon_id.map({900020: "gca00020", 900070: "gca00070"}), df.set)
    old_share = df.span_mm / df.segment_mm
    new_share = old_share / np.where((df.inside_share > 0) & (df.inside_share <= 1), df.inside_share, 1.0)
    for name, share in (("shipped", old_share), ("changed", new_share)):
        est = np.where(share.round(4) < 0.9, df.estimate * share, df.estimate)
        df[name] = 100 * np.abs(est - df.true)
    rows = {c: g[["shipped", "changed"]].mean() for c, g in df.groupby("cell")}
    rows["gca00020 + gca00070"] = df[df.set == "V_real"][["shipped", "changed"]].mean()
    t = pd.DataFrame(rows).T.assign(n=df.groupby("cell").size())
    t["change"] = t.changed - t.shipped
    print("known-length MAE, points, both noise levels pooled:")
    print(t.round(2).to_string())
    print("inside_share under 0.99:", df.groupby("cell").inside_share.apply(lambda x: (x < 0.99).mean()).round(3)
          .to_dict())


if sys.argv[1:] == ["--measure"]:
    measure()
    sys.exit()
cap = {}
_fh = M.from_heatmap


def fh(heatmap, grid, points, *a, **k):
    est = _fh(heatmap, grid, points, *a, **k)
    cap["grid"], cap["points"] = grid, np.asarray(points, float)
    return est


M.from_heatmap = fh
_complete = M.complete


def complete(*a, **k):
    comp = _complete(*a, **k)
    cap["planes"] = comp.planes
    return comp


M.complete = complete
ds, n = sys.argv[1], int(sys.argv[2])
d = pd.read_csv(f"data/{ds}/completion-estimates-6d813b3c4351-steps=10-signals4.csv")
d = d[d.noise_mm == 0]
d = d.sample(min(n, len(d)), random_state=1)
m = CompletionMethod(None)
m.intervals = None
rows = []
for _, r in d.iterrows():
    with Shard(Path("data") / ds / r.shard) as s:
        g = s.geometry(int(r["index"]))
    est = m.estimate(g["partial_points"])
    inside = inside_planes(cap["grid"].to_voxel(cap["points"]), cap["planes"]).mean()
    rows.append(dict(colon=r.colon_id, end=r.hole_model.endswith("+end"), L=r.segment_mm, true=r.true,
                     est=est.coverage, span=est.signals["span_mm"], inside=inside, cached=r.estimate))
o = pd.DataFrame(rows)
o.to_csv(f"/tmp/probe0173-{ds}.csv", index=False)
f0 = o.span / o.L
f1 = f0 / o.inside.clip(lower=1e-3)
e0 = np.where(f0 < 0.9, o.est * f0, o.est)
e1 = np.where(f1 < 0.9, o.est * f1, o.est)
o["ae0"], o["ae1"], o["aen"] = 100 * abs(e0 - o.true), 100 * abs(e1 - o.true), 100 * abs(o.est - o.true)
print("same estimate as cached:", np.allclose(o.est, o.cached, atol=1e-6))
print(o.groupby(["colon", "end"])[["aen", "ae0", "ae1", "inside"]].agg(["mean"]).round(2).to_string())
print(o[["aen", "ae0", "ae1"]].mean().round(2).to_string())
