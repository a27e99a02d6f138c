"""Decision 0156: the chosen calibration on the suites (reported, not used to choose) from the session's tables."""
import json, sys
import numpy as np, pandas as pd
sys.path.insert(0, "/work/main/scripts")
import calibrate_intervals as ci
from colonbench.completion import intervals
cal = intervals.Intervals(**json.load(open(sys.argv[1])))
for suite in sys.argv[2:]:
    try:
        df = pd.read_csv(f"/tmp/cb/probe/feat-{suite}.csv").rename(columns={"unwrap": "unwrap_coverage", "threshold": "threshold_coverage"})
    except FileNotFoundError:
        continue
    sig = ci.signals(df)
    lohi = np.array([cal.interval(c, s) for c, s in zip(df["estimate"], sig)])
    df["inside"] = (lohi[:, 0] - 1e-12 <= df["true"]) & (df["true"] <= lohi[:, 1] + 1e-12)
    df["width"] = lohi[:, 1] - lohi[:, 0]
    df["big"] = (df["estimate"] - df["true"]).abs() > 0.15
    df["flag"] = df["width"] > cal.review_width
    g = df.groupby("noise_mm").agg(n=("inside", "size"), inside=("inside", "mean"), width=("width", "mean"),
                                   mae=("estimate", lambda e: np.nan), big=("big", "sum"), flagged=("flag", "sum"),
                                   caught=("big", lambda b: (b & df.loc[b.index, "flag"]).sum()))
    g["mae"] = df.assign(e=(df["estimate"] - df["true"]).abs()).groupby("noise_mm")["e"].mean() * 100
    g["inside"] *= 100; g["width"] *= 100
    g["recall"] = 100 * g["caught"] / g["big"].clip(lower=1); g["precision"] = 100 * g["caught"] / g["flagged"].clip(lower=1)
    print(suite); print(g.round(1).to_string())
