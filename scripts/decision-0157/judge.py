"""Decision 0157's session script: a model's completion estimates of a dataset's segments at 0 and 0.5 mm (its
intervals off), paired later with the shipped model's.

    python judge.py MODEL DATA SPLIT OUT.csv
"""
import sys

import pandas as pd

from colonbench.benchmark.evaluate import noisy, select
from colonbench.completion.method import CompletionMethod
from colonbench.errors import ColonbenchError
from colonbench.shards.reader import Shard

model, data, split, out = sys.argv[1:5]
m = CompletionMethod(None if model == "small" else model)
m.intervals = None
_, picks = select(data, split)
rows = []
for name, indices in picks:
    with Shard(f"{data}/{name}") as sh:
        for i in indices:
            geo = sh.geometry(i)
            for sigma in (0.0, 0.5):
                try:
                    c = m.estimate(noisy(geo["partial_points"], sigma, 0, name, i)).coverage
                except ColonbenchError:
                    c = float("nan")
                rows.append({"shard": name, "index": i, "colon_id": geo["colon_id"], "noise_mm": sigma,
                             "hole_model": geo["hole_model"], "true": geo["coverage"], "estimate": c})
pd.DataFrame(rows).to_csv(out, index=False)
print(out, len(rows))
