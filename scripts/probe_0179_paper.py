"""Decision record 0179's probe (one-off, removed after): where the paper-like colons' held-out intervals hold more
than 95 %: per dataset, hole model and likeness group, the held-out intervals of the shipped scheme on the committed
table of calibration estimates.

Run from the repository root (about a minute): ``python scripts/probe_0179_paper.py``.
"""
import sys
sys.path.insert(0, "scripts")
import numpy as np, pandas as pd
import calibrate_intervals as ci
from colonbench.completion import caltable, intervals, likeness
from colonbench.completion.method import model_path, steps_version

df = ci.with_units(ci.with_sets(caltable.read(caltable.path_for(model_path(None), steps_version()), ci.SIGNALS)))
cal_df = df[df["set"].isin(ci.CALIBRATED)].reset_index(drop=True)
held = ci.by_colon(cal_df, ci.KEEP, intervals.LEVEL)
sig, est, colons = ci.signals(cal_df), cal_df["estimate"].to_numpy(float), cal_df["colon"].to_numpy()
like = np.empty(len(cal_df), int)
for colon in np.unique(colons):
    fit_on, test_on = np.flatnonzero(colons != colon), np.flatnonzero(colons == colon)
    part = cal_df.iloc[fit_on]
    cal = ci.fit_scheme(part, est[fit_on], [sig[k] for k in fit_on], ci.KEEP, 1.0, intervals.LEVEL,
                        ci.unit_weights(part), colons[fit_on])
    like[test_on] = [int(intervals.looks_like(cal.like, est[k], sig[k])) for k in test_on]
held = held.assign(like=like, width_pts=100 * held["width"], error_pts=100 * (held["true"] - held["estimate"]).abs())
pd.set_option("display.width", 200)
print(held.groupby(["cell", "manifest", "hole_model", "like"]).agg(
    n=("inside", "size"), inside=("inside", "mean"), width=("width_pts", "mean"), error=("error_pts", "mean"))
    .round(3).to_string())
pm = held[held["manifest"] == "calibration-paper-more"]
print("\ncalibration-paper-more (made as paper-v1 is): inside", pm.groupby("noise_mm")["inside"].mean().round(3).to_dict(),
      "like=1 share", round(float((pm["like"] == 1).mean()), 3))
