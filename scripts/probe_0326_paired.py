"""Decision record 0326's probe: coverage MAE per real validation colon and paired per-segment differences.

    python scripts/probe_0326_paired.py BASE_RUN RUN... (run folders of colonbench evaluate data/validation-real)
"""
import sys

import numpy as np
import pandas as pd


def load(run):
    d = pd.read_csv(f"{run}/results/completion.csv")
    d["colon"] = d.shard.str.extract(r"(gca\d+)")[0]
    d["ae"] = (d.coverage - d.true_coverage).abs() * 100
    return d.set_index(["sample_id", "noise_mm"])


base = load(sys.argv[1])
for run in sys.argv[1:]:
    d = load(run)
    out = []
    for c, b in base.groupby("colon"):
        x = d.loc[b.index]
        diff = (x.ae - b.ae).dropna()
        se = diff.std(ddof=1) / np.sqrt(len(diff)) if len(diff) > 1 else 0.0
        out.append(f"{c}: MAE {x.ae.mean():.2f} bias {100 * (x.coverage - x.true_coverage).mean():+.2f}, "
                   f"against the base {diff.mean():+.2f} +- {se:.2f}")
    print(run, " | ".join(out))
