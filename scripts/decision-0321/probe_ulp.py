"""Perturb every input coordinate at the last bit (a function of its value, so equal points stay equal) and see how
each method's coverage moves on demo-v1."""
import sys, numpy as np
from colonbench.benchmark import suites
from colonbench.benchmark.evaluate import noisy, select
from colonbench.benchmark.registry import load_method
from colonbench.shards.reader import Shard
data = suites.data_dir(suites.get("demo-v1"), "/tmp/cb/suites")
names = sys.argv[1].split(",")
ms = {n: load_method(n) for n in names}
for m in ms.values():
    m.estimate(np.random.default_rng(1).normal(size=(500, 3)) * [30, 10, 10])
_, picks = select(data, "test")
def ulp(p, k):
    bits = p.view(np.int64)
    up = ((bits >> k) & 1).astype(bool)
    return np.where(up, np.nextafter(p, np.inf), np.nextafter(p, -np.inf))
diffs = {n: [] for n in names}
for name, idx in picks:
    with Shard(data / name) as sh:
        for i in idx:
            geo = sh.geometry(i)
            for sigma in (0.0, 0.5):
                p = noisy(geo["partial_points"], sigma, 0, name, i)
                for n, m in ms.items():
                    base = m.estimate(p).coverage
                    vals = [m.estimate(ulp(p, k)).coverage for k in range(int(sys.argv[2]))]
                    d = np.max(np.abs(np.array(vals) - base)); diffs[n].append(d)
                    if d > 1e-6: print(n, name, i, sigma, d, flush=True)
for n in names:
    d = np.array(diffs[n]); print(n, "max", d.max(), "mean", d.mean(), "rows moved >1e-6:", (d > 1e-6).sum(), "of", len(d))
