"""Decision record 0189's measurement (a one-off probe, removed after it): the likeness classifier fitted with its
two classes weighing the same, held out on the committed table of calibration estimates. Adapted from 0182's probe
(git show f8718e5:scripts/probe_0182_sphere_group.py). Run from the repository root:

    python scripts/probe_0189_balanced.py [TABLE]   (default: the shipped model's table, checked)
"""
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import calibrate_intervals as ci                                          # noqa: E402
from colonbench.completion import caltable, intervals, likeness           # noqa: E402
from colonbench.completion.conformal import effective_size               # noqa: E402
from colonbench.completion.method import model_path, steps_version       # noqa: E402

#: candidate -> (the classifier's extra features, whether it learns V_paper's sphere-hole estimates only, balanced)
CANDIDATES = {"0": ((), False, False), "8 spheres, balanced": ((), True, True),
              "9 spheres + three, balanced": (("log_gap", "misfit", "unfilled"), True, True),
              "10 V_paper, balanced": ((), False, True)}


def balanced(w, like):
    """``w`` rescaled so that the estimates ``like`` marks and the others weigh the same in total."""
    w, like = np.asarray(w, float), np.asarray(like, bool)
    total = w.sum()
    return np.where(like, 0.5 * total / w[like].sum(), 0.5 * total / w[~like].sum()) * w


def fit_with(extra, balance):
    """likeness.fit with the classifier reading the scale's features and ``extra``, its classes balanced or not."""
    def fit(true, estimated, signals, scheme, review_width, level, weights, colons, like):
        threshold, base = likeness.split_scheme(scheme)
        cal = intervals.fit(true, estimated, signals, base, review_width, level, weights=weights, colons=colons)
        names = intervals.scale_features(base)
        estimated = np.asarray(estimated, float)
        x = np.array([intervals.features(c, s, names) for c, s in zip(estimated, signals)])
        xl = np.array([intervals.features(c, s, names + extra) for c, s in zip(estimated, signals)])
        w, c = intervals._unit_weights(base, weights, colons, len(estimated))
        cal.scheme, cal.like = scheme, likeness.fit_like(xl, like, balanced(w, like) if balance else w, names + extra,
                                                         threshold)
        group = np.array([intervals.looks_like(cal.like, e, s, f) for e, s, f in zip(estimated, signals, xl)])
        residual = np.asarray(true, float) - estimated
        for value in (1, 0):
            sel = group == value
            if effective_size(w[sel]) >= intervals.MIN_GROUP:
                cal.groups[f"like={value}"] = intervals._fit_group(
                    residual[sel], x[sel], names, level, intervals._two_sided(intervals._scaled(base)), w[sel],
                    c[sel], intervals._binned(intervals._scaled(base)), intervals._tau(intervals._scaled(base)))
        return cal
    return fit


def label_with(spheres):
    """ci.fit_scheme with the likeness label V_paper's estimates, or V_paper's sphere-hole estimates only."""
    def fit_scheme(part, estimated, sig, scheme, review_width, level, weights, colons):
        like = (part["set"] == "V_paper").to_numpy()
        if spheres:
            like = like & (part["hole_model"] == "spheres").to_numpy()
        return likeness.fit(part["true"].to_numpy(float), estimated, sig, scheme, review_width, level, weights,
                            colons, like)
    return fit_scheme


def held(df, scheme):
    """ci.by_colon's held-out intervals, with each row's likeness group."""
    out, sig = df.copy(), ci.signals(df)
    est, colons = df["estimate"].to_numpy(float), df["colon"].to_numpy()
    low, high, like = np.empty(len(df)), np.empty(len(df)), np.empty(len(df), int)
    for colon in np.unique(colons):
        fit_on, test_on = np.flatnonzero(colons != colon), np.flatnonzero(colons == colon)
        part = df.iloc[fit_on]
        cal = ci.fit_scheme(part, est[fit_on], [sig[k] for k in fit_on], scheme, 1.0, intervals.LEVEL,
                            ci.unit_weights(part), colons[fit_on])
        for k in test_on:
            low[k], high[k] = cal.interval(est[k], sig[k])
            like[k] = int(intervals.looks_like(cal.like, est[k], sig[k]))
    out["low"], out["high"], out["like"] = low, high, like
    out["inside"] = (out["low"] - 1e-12 <= out["true"]) & (out["true"] <= out["high"] + 1e-12)
    out["width"] = out["high"] - out["low"]
    return out


def main():
    path = model_path(None)
    saved = Path(sys.argv[1]) if len(sys.argv) > 1 else caltable.path_for(path, steps_version())
    df = ci.with_units(ci.with_sets(caltable.read(saved, ci.SIGNALS, None if len(sys.argv) > 1 else
                                                  ci.table_source(path))))
    cal_df = df[df["set"].isin(ci.CALIBRATED)].reset_index(drop=True)
    print(f"table {saved.name}: {len(cal_df)} calibrated estimates")

    scheme = ci.KEEP
    for name, (extra, spheres, balance) in CANDIDATES.items():
        likeness.fit = fit_with(extra, balance)
        ci.fit_scheme = label_with(spheres)
        h = held(cal_df, scheme)
        s = ci.summarise({name: h}, intervals.LEVEL, show=False)[name]
        pm = h[h["manifest"] == "calibration-paper-more"]
        real = h[h["set"] == "V_real"]
        print(f"\n[{name}] all cells 85-95: {s['ok']}; shortfall {s['shortfall']}; real width {s['real_width']}")
        print("  " + "; ".join(f"{k} {v['inside']} ({v['width']})" for k, v in s["cells"].items()))
        print(f"  paper-more inside by noise {(100 * pm.groupby('noise_mm')['inside'].mean()).round(1).to_dict()}, "
              f"mean {100 * pm.groupby('noise_mm')['inside'].mean().mean():.2f}; like=1 {100 * pm['like'].mean():.1f} %; "
              f"width {100 * pm['width'].mean():.1f}")
        print(f"  like=1 share: real {(100 * real.groupby('cell')['like'].mean()).round(1).to_dict()}, "
              f"V_paper {100 * h.loc[h['set'] == 'V_paper', 'like'].mean():.1f}, "
              f"V_wide {100 * h.loc[h['set'] == 'V_wide', 'like'].mean():.1f}")
        print(f"  V_paper by hole model: {(100 * h[h['set'] == 'V_paper'].groupby('hole_model')['inside'].mean()).round(1).to_dict()}",
              flush=True)
        print(f"  V_paper by hole model and group: "
              f"{h[h['set'] == 'V_paper'].groupby(['hole_model', 'like'])['inside'].agg(['size', 'mean']).round(3).to_dict('index')}")
        print(f"  paper-more width by hole model: "
              f"{(100 * pm.groupby('hole_model')['width'].mean()).round(1).to_dict()}", flush=True)


if __name__ == "__main__":
    main()
