"""Decision record 0167's probe (a one-off): review by the fitted odds of a far-off estimate, held out leave one colon
out, against the shipped review (``reach``) on the same held-out intervals.

    python scripts/probe_0167_review_odds.py
"""

from pathlib import Path

import numpy as np
import pandas as pd
from scipy.optimize import minimize

import calibrate_intervals as ci
from colonbench.completion import intervals
from colonbench.completion.method import model_path, steps_version
from colonbench.shards.schema import sha256_file

SCHEME, LAMBDA = "binned-colon-novel-depth-shift", 1e-3


def table() -> pd.DataFrame:
    path, parts = model_path(None), []
    for name in ci.MANIFESTS:
        cache = Path("data") / name / f"completion-estimates-{sha256_file(path)[:12]}-{steps_version()}-signals4.csv"
        part = pd.read_csv(cache).assign(manifest=name, set=ci.MANIFESTS[name])
        if name == "calibration":
            part.loc[part["colon_id"] >= ci.REAL_IDS, "set"] = "train_real"
        parts.append(part)
    df = ci.with_units(pd.concat(parts, ignore_index=True))
    return df[df["set"].isin(ci.CALIBRATED)].reset_index(drop=True)


def logistic(x, y, w):
    """Weighted logistic regression, ridge LAMBDA on all weights but the first (the intercept)."""
    w = w / w.sum()

    def loss(b):
        z = x @ b
        p = 1.0 / (1.0 + np.exp(-z))
        pen = np.r_[0.0, b[1:]]
        return (float(np.sum(w * (np.logaddexp(0.0, z) - y * z))) + 0.5 * LAMBDA * float(pen @ pen),
                x.T @ (w * (p - y)) + LAMBDA * pen)

    return minimize(loss, np.zeros(x.shape[1]), jac=True, method="L-BFGS-B").x


def held_odds(df: pd.DataFrame) -> np.ndarray:
    names = intervals.SCALE_FEATURES[SCHEME]
    x = np.array([intervals.features(c, s, names) for c, s in zip(df["estimate"], ci.signals(df))])
    y = ((df["true"] - df["estimate"]).abs() > ci.BIG).to_numpy(float)
    colons, out = df["colon"].to_numpy(), np.empty(len(df))
    for colon in np.unique(colons):
        fit, test = colons != colon, colons == colon
        lo, hi = x[fit].min(axis=0), x[fit].max(axis=0)
        b = logistic(x[fit], y[fit], ci.unit_weights(df[fit]))
        out[test] = np.clip(x[test], lo, hi) @ b
    return out


def threshold(held: pd.DataFrame, score: pd.Series) -> tuple[float, dict]:
    """review_width's choice on any score: the highest threshold catching REVIEW_RECALL in each review cell."""
    big = (held["true"] - held["estimate_used"]).abs() > ci.BIG
    cells = {c: held["cell"] == c for c in ci.review_cells(held)}
    for t in np.unique(np.round(score, 6))[::-1]:
        flag = score > t - 1e-12
        if min(float((flag & big & s).sum() / max((big & s).sum(), 1)) for s in cells.values()) >= ci.REVIEW_RECALL:
            break
    report = {}
    for c in sorted(held["cell"].unique()):
        s = held["cell"] == c
        report[c] = {"flagged": round(100 * float((flag & s).mean() / s.mean()), 1),
                     "recall": round(100 * float((flag & big & s).sum() / max((big & s).sum(), 1)), 1),
                     "precision": round(100 * float((flag & big & s).sum() / max((flag & s).sum(), 1)), 1),
                     "off": int((big & s).sum())}
    return float(t), report


def main() -> None:
    df = table()
    held = ci.by_colon(df, SCHEME, 0.9)
    reach = pd.Series([intervals.review_score(c, lo, hi, "reach") for c, lo, hi in
                       zip(held["estimate_used"], held["low"], held["high"])], index=held.index)
    odds = pd.Series(held_odds(df), index=held.index)
    figure = {}
    for name, score in (("reach", reach), ("odds", odds)):
        t, report = threshold(held, score)
        figure[name] = min(report[c]["precision"] for c in report if c.startswith("V_real "))
        print(f"\n{name}: threshold {t:.4f}; lower real precision {figure[name]:.1f} %")
        print(pd.DataFrame(report).T.to_string())
    gain = figure["odds"] - figure["reach"]
    print(f"\nodds - reach: {gain:+.1f} points: {'adopted' if gain > 3.0 else 'not adopted'} (0167: more than 3)")


if __name__ == "__main__":
    main()
