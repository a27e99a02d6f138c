"""Decision record 0164's probe: 0326's and 0162's paired differences on the real validation colons, split into
segments with an unseen end (hole models ``...+end``) and without.

    python scripts/probe_0164_ends.py val-H64:val-W64 ... (NEW:BASE, run folders under runs/ of colonbench evaluate
                                                          data/validation-real --split validation --noise 0.5)
"""
import sys
import numpy as np
import pandas as pd


def load(run):
    d = pd.read_csv(f"{run}/results/completion.csv")
    d["colon"] = d.shard.str.extract(r"(gca\d+)")[0]
    d["ae"] = (d.coverage - d.true_coverage).abs() * 100
    d["end"] = d.hole_model.str.contains("end")
    return d.set_index(["sample_id", "noise_mm"])


for pair in sys.argv[1:]:
    new, base = (load(f"runs/{r}") for r in pair.split(":"))
    cells = []
    for (c, end), b in base.groupby(["colon", "end"]):
        x = new.loc[b.index]
        diff = (x.ae - b.ae).dropna()
        se = diff.std(ddof=1) / np.sqrt(len(diff))
        cells.append(f"{c} {'end' if end else 'whole'} (n {len(diff)}): {b.ae.mean():.2f} -> {x.ae.mean():.2f}, "
                     f"{diff.mean():+.2f} +- {se:.2f}")
    print(pair, "\n  " + "\n  ".join(cells))
