"""Decision record 0184's measurement (a one-off probe, removed after it): the review's held-out odds on the real
validation colons' segments without an erased end. Run from the repository root (a few minutes):

    python scripts/probe_0184_review.py
"""
import sys
from pathlib import Path

import numpy as np
from scipy.stats import mannwhitneyu

sys.path.insert(0, str(Path(__file__).resolve().parent))
import calibrate_intervals as ci                                          # noqa: E402
from colonbench.completion import caltable, intervals                     # noqa: E402
from colonbench.completion.calfile import load                           # noqa: E402
from colonbench.completion.method import model_path, steps_version       # noqa: E402

SHIPPED = -1.403001


def report(name, df, score):
    far = ((df["true"] - df["estimate"]).abs() > ci.BIG).to_numpy()
    s = score.to_numpy()
    print(f"\n[{name}]")
    best = None
    for t in np.unique(np.round(s, 4))[::-1]:
        rows = []
        for colon, g in df.groupby("cell"):
            m = (df["cell"] == colon).to_numpy()
            flag = s > t - 1e-12
            caught = (flag & far & m).sum() / max((far & m).sum(), 1)
            right = (flag & far & m).sum() / max((flag & m).sum(), 1)
            rows.append((caught, right))
        if min(r[0] for r in rows) >= 0.70:
            best = (t, rows)
            break
    for colon, g in df.groupby("cell"):
        m = (df["cell"] == colon).to_numpy()
        y, x = far[m], s[m]
        auc = mannwhitneyu(x[y], x[~y]).statistic / (y.sum() * (~y).sum())
        flag = x > SHIPPED - 1e-12
        print(f"  {colon}: {m.sum()} estimates, {y.sum()} far off; AUC {auc:.3f}; at the shipped threshold caught "
              f"{100 * (flag & y).sum() / max(y.sum(), 1):.1f} %, right {100 * (flag & y).sum() / max(flag.sum(), 1):.1f} %"
              f", flagged {100 * flag.mean():.1f} %")
    if best:
        t, rows = best
        print(f"  (b) the threshold that catches 70 % on each colon: log odds {t:.3f}: "
              + "; ".join(f"caught {100 * c:.1f} %, right {100 * r:.1f} %" for c, r in rows))


def main():
    path = model_path(None)
    df = ci.with_units(ci.with_sets(caltable.read(caltable.path_for(path, steps_version()), ci.SIGNALS,
                                                  ci.table_source(path))))
    cal = df[df["set"].isin(ci.CALIBRATED)].reset_index(drop=True)
    names = intervals.scale_features(ci.KEEP)
    assert list(names) == load(path, steps_version()).review_odds["features"]
    odds = ci.held_odds(cal, names)
    both = ~cal["hole_model"].str.endswith("+end")
    real = (cal["set"] == "V_real").to_numpy()
    report("(a, b) shipped odds, held out, all segments", cal[real], odds[real])
    report("(a, b) shipped odds, held out, no erased end", cal[real & both], odds[real & both])
    sub = cal[both].reset_index(drop=True)
    refit = ci.held_odds(sub, names)
    r = (sub["set"] == "V_real").to_numpy()
    report("(c) odds refitted without erased ends, held out, no erased end", sub[r], refit[r])


if __name__ == "__main__":
    main()
