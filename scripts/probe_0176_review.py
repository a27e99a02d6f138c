"""Decision record 0176's probe (one-off, removed after): where the shipped review's catches, misses and false flags
lie on the real validation colons held out, by hole model.

Run from the repository root after ``python scripts/calibrate_intervals.py`` has cached its estimates (about two
minutes): ``python scripts/probe_0176_review.py``.
"""
import sys
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))
import calibrate_intervals as ci  # noqa: E402
from colonbench.completion import calfile, intervals  # noqa: E402
from colonbench.completion.method import CompletionMethod, model_path, steps_version  # noqa: E402
from colonbench.shards.schema import sha256_file  # noqa: E402

path = model_path(None)
data = [(name, Path("data") / name) for name in ci.MANIFESTS]
df = ci.with_units(ci.table(data, CompletionMethod(None), path))
cal_df = df[df["set"].isin(ci.CALIBRATED)].reset_index(drop=True)
cal = calfile.load(path, steps_version())
held = ci.by_colon(cal_df, cal.scheme, cal.level)
score = np.array([intervals.review_score(c, lo, hi, cal.review_by)
                  for c, lo, hi in zip(held["estimate_used"], held["low"], held["high"])])
held["flag"] = score > cal.review_width - 1e-12
held["far"] = (held["true"] - held["estimate_used"]).abs() > ci.BIG
held["end"] = np.where(held["hole_model"].str.endswith("+end"), "+end", "no +end")
print(f"the shipped review ({cal.review_by} over {100 * cal.review_width:.1f} points) on held-out intervals of "
      f"{cal.scheme}")
real = held[held["set"] == "V_real"]
for name, g in [("both real colons", real)] + list(real.groupby("cell")):
    rows = []
    for part, h in [("all", g)] + list(g.groupby("end")):
        rows.append({"part": part, "n": len(h), "far": int(h.far.sum()), "caught": int((h.far & h.flag).sum()),
                     "flagged": int(h.flag.sum()),
                     "recall": round(100 * (h.far & h.flag).sum() / max(h.far.sum(), 1), 1),
                     "precision": round(100 * (h.far & h.flag).sum() / max(h.flag.sum(), 1), 1),
                     "span / segment of the far": round(float((h.span_mm / h.segment_mm)[h.far].median()), 2)})
    print(f"\n{name}:\n" + pd.DataFrame(rows).to_string(index=False))
