"""Decision record 0190's measurement (a one-off probe, removed after it): the known-length interval fitted within
the likeness groups, held out on the committed table of calibration estimates. Run from the repository root:

    python scripts/probe_0190_known_like.py
"""
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import calibrate_intervals as ci                                                    # noqa: E402
from colonbench.completion import caltable, intervals, known_extent, likeness       # noqa: E402
from colonbench.completion.conformal import effective_size                         # noqa: E402
from colonbench.completion.method import model_path, steps_version                 # noqa: E402

BASE = likeness.base(ci.KEEP)
EXTRA = known_extent.KNOWN_EXTRA["K3"]


def held_known(df, mode):
    """Each row's held-out known-length interval under ``mode`` (K3, K4, K5), with its likeness group."""
    out = df.copy()
    sig, plain = ci.known_signals(df), ci.signals(df)
    est, est_plain = ci.known_estimates(df, sig), df["estimate"].to_numpy(float)
    true, colons = df["true"].to_numpy(float), df["colon"].to_numpy()
    scaled = intervals._scaled(BASE)
    names = intervals.SCALE_FEATURES[scaled] + tuple(EXTRA)
    x_all = np.array([intervals.features(e, s, names) for e, s in zip(est, sig)])
    low, high, like_of = np.empty(len(df)), np.empty(len(df)), np.zeros(len(df), int)
    for colon in np.unique(colons):
        fit_on, test_on = np.flatnonzero(colons != colon), np.flatnonzero(colons == colon)
        part = df.iloc[fit_on]
        w, c = ci.unit_weights(part), colons[fit_on]
        main = ci.fit_scheme(part, est_plain[fit_on], [plain[k] for k in fit_on], ci.KEEP, 1.0, intervals.LEVEL, w, c)
        cal = intervals.Intervals(BASE, intervals.LEVEL, {}, 1.0)
        known_extent.fit_known(cal, true[fit_on], est[fit_on], [sig[k] for k in fit_on], w, c, EXTRA, True)
        like = np.array([intervals.looks_like(main.like, est[k], sig[k]) for k in range(len(df))])
        short = known_extent.shortened(sig)
        ww, cc = intervals._unit_weights(BASE, w, c, len(fit_on))
        resid, x = true[fit_on] - est[fit_on], x_all[fit_on]
        groups = {}
        if mode != "K3":
            keys = [(lk, sh) for lk in (0, 1) for sh in (0, 1)] if mode == "K4" else [(0, None), (1, None)]
            for lk, sh in keys:
                sel = (like[fit_on] == lk) & (True if sh is None else short[fit_on] == sh)
                if effective_size(ww[sel]) >= intervals.MIN_GROUP:
                    groups[(lk, sh)] = intervals.fit_subgroup(resid, x, names, intervals.LEVEL, scaled, ww, cc, sel)
        for k in test_on:
            key = (int(like[k]), None if mode == "K5" else int(short[k]))
            g = groups.get(key)
            if g is None:
                lo, hi = cal.quantiles(est[k], {**sig[k], "extent": "known"})
            else:
                lo, hi = intervals._scale(g, est[k], sig[k])
            low[k], high[k] = np.clip(est[k] + lo, 0, 1), np.clip(est[k] + hi, 0, 1)
            like_of[k] = int(like[k])
    out["low"], out["high"], out["like"] = low, high, like_of
    out["inside"] = (out["low"] - 1e-12 <= out["true"]) & (out["true"] <= out["high"] + 1e-12)
    out["width"] = out["high"] - out["low"]
    return out


def main():
    path = model_path(None)
    df = ci.with_units(ci.with_sets(caltable.read(caltable.path_for(path, steps_version()), ci.SIGNALS,
                                                  ci.table_source(path))))
    cal_df = df[df["set"].isin(ci.CALIBRATED)].reset_index(drop=True)
    print(f"{len(cal_df)} calibrated estimates")
    shipped = ci.by_colon(cal_df, BASE, intervals.LEVEL, known=True, extra=EXTRA, short=True)
    for mode in ("K3", "K4", "K5"):
        h = held_known(cal_df, mode)
        if mode == "K3":
            assert np.allclose(h["low"], shipped["low"]) and np.allclose(h["high"], shipped["high"]), "K3 differs"
        s = ci.summarise({mode: h}, intervals.LEVEL, show=False)[mode]
        video, pm = h[h["hole_model"] == "video"], h[h["manifest"] == "calibration-paper-more"]
        vi, pi = video.groupby("noise_mm")["inside"].mean() * 100, pm.groupby("noise_mm")["inside"].mean() * 100
        print(f"\n[{mode}] all cells 85-95: {s['ok']}; shortfall {s['shortfall']}; real width {s['real_width']}")
        print("  " + "; ".join(f"{k} {v['inside']} ({v['width']})" for k, v in s["cells"].items()))
        print(f"  video partials inside {vi.round(1).to_dict()}, mean {vi.mean():.2f}; width "
              f"{100 * video['width'].mean():.1f}; like=1 {100 * video['like'].mean():.1f} %")
        print(f"  video by set: {(100 * video.groupby('set')['inside'].mean()).round(1).to_dict()}, width "
              f"{(100 * video.groupby('set')['width'].mean()).round(1).to_dict()}")
        print(f"  paper-more inside {pi.round(1).to_dict()}, mean {pi.mean():.2f}; width {100 * pm['width'].mean():.1f}")
        print(f"  by group (like): {h.groupby('like')[['inside', 'width']].mean().round(3).to_dict('index')}",
              flush=True)


if __name__ == "__main__":
    main()
