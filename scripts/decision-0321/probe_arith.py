"""Another machine's arithmetic, modelled by the eager network against the one made fast for inference (their sums
differ in the last bits, as another CPU's do): how far each method built on the network moves, per row."""
import sys, numpy as np, pandas as pd
from colonbench.benchmark import suites
from colonbench.benchmark.evaluate import noisy, select
from colonbench.benchmark.registry import load_method
from colonbench.benchmark.metrics import segment_metrics
from colonbench.benchmark.evaluate import _truth
from colonbench.shards.reader import Shard
suite = sys.argv[3] if len(sys.argv) > 3 else "demo-v1"
data = suites.data_dir(suites.get(suite), "/tmp/cb/suites")
names = sys.argv[1].split(",")
ms = {n: load_method(n) for n in names}
pred = ms[names[0]].predictor
pred(np.random.default_rng(1).normal(size=(500, 3)) * [30, 10, 10])
_, picks = select(data, "test")
limit = int(sys.argv[2])
rows = []
for name, idx in picks:
    with Shard(data / name) as sh:
        for i in idx[:limit]:
            geo = sh.geometry(i)
            truth = _truth(sh, i, geo, False)
            for sigma in (0.0, 0.5):
                p = noisy(geo["partial_points"], sigma, 0, name, i)
                out = {}
                for mode in ("fast", "eager"):
                    pred._cache.clear()
                    if mode == "eager":
                        saved = dict(pred._forward); pred._forward = {64: pred.net}
                    for n, m in ms.items():
                        e = m.estimate(p)
                        met = segment_metrics(e.coverage, e.holes, e.centerline, truth)
                        out[(n, mode)] = {"coverage": e.coverage, **met, "n_holes": len(e.holes), "n_cl": len(e.centerline)}
                    if mode == "eager":
                        pred._forward = saved
                for n in names:
                    a, b = out[(n, "fast")], out[(n, "eager")]
                    rows.append({"method": n, "shard": name, "index": i, "sigma": sigma, **{k: b[k] - a[k] for k in a},
                                 "n_holes_a": a["n_holes"], "n_cl_a": a["n_cl"], "n_gt_holes": len(truth["hole_points"]), "n_gt_cl": len(truth["centerline"])})
df = pd.DataFrame(rows)
df.to_csv(f"/tmp/cb/arith-{suite}.csv", index=False)
cols = [c for c in df.columns if c.startswith(("coverage", "holes_", "centerline_"))]
print(df.groupby("method")[cols].agg(lambda x: np.nanmax(np.abs(x))).T.to_string())
print(df.assign(moved=df["coverage"].abs() > 1e-6).groupby("method")["moved"].sum())
