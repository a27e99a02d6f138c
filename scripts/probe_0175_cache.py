"""Decision record 0175's second probe (one-off, removed after): the Context's figures from the shipped calibration
and results, and the fill tables again with the signal as it ships (``rim_fill`` of the estimates cache).

Run from the repository root after ``python scripts/calibrate_intervals.py`` has cached its estimates (seconds):
``python scripts/probe_0175_cache.py``.
"""
import sys
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))
import calibrate_intervals as ci  # noqa: E402
from colonbench.completion import calfile  # noqa: E402
from colonbench.completion.method import CompletionMethod, model_path, steps_version  # noqa: E402

paper = pd.read_csv("benchmark/shipped_results/paper-v1/results/completion.csv")
paper["inside"] = (paper.interval_low <= paper.true_coverage) & (paper.true_coverage <= paper.interval_high)
paper["width"] = paper.interval_high - paper.interval_low
paper["error"] = paper.coverage_error.abs()
print("paper-v1 as shipped, by hole model:")
print(paper.groupby(["hole_model", "noise_mm"]).agg(n=("inside", "size"), inside=("inside", "mean"),
                                                    width=("width", "mean"), mae=("error", "mean")).round(3).to_string())

path = model_path(None)
df = ci.with_units(ci.table([(n, Path("data") / n) for n in ci.MANIFESTS], CompletionMethod(None), path))
df = df[df.set.isin(ci.CALIBRATED)]
cal = calfile.load(path, steps_version())
lh = np.array([cal.interval(e, s) for e, s in zip(df.estimate, ci.signals(df))])
df["inside"] = (lh[:, 0] - 1e-12 <= df.true) & (df.true <= lh[:, 1] + 1e-12)
print("\nthe shipped calibration on its own paper-like colons (in-sample), by hole model:")
print(df[df.set == "V_paper"].groupby("hole_model").agg(n=("inside", "size"), inside=("inside", "mean")).round(3)
      .to_string())

zero = df[df.noise_mm == 0].copy()
zero["far"] = (zero.estimate - zero.true).abs() > ci.BIG
zero["band"] = pd.cut(zero.rim_fill, [-0.01, 0.55, 0.75, 0.9, 1.0])
print("\nestimates off by more than 15 points by rim_fill as it ships, without noise:")
print(zero.groupby(["cell", "band"], observed=True).agg(n=("far", "size"), far=("far", "mean")).round(3).to_string())
far = zero[zero.far & (zero.set == "V_real")]
print(f"\nthe real colons' far-off estimates: {len(far)}; by hole model, with their median rim_fill:")
print(far.groupby("hole_model").agg(n=("rim_fill", "size"), fill=("rim_fill", "median")).round(3).to_string())
