"""Decision record 0185's measurement (a one-off probe, removed after it): signals of a completed wall unlike its
points, screened for the review's far-off estimates where both ends were seen, then the review odds with them held
out. Run from the repository root with the calibration's datasets in data/:

    python scripts/probe_0185_area.py make STAGE PART PARTS   (STAGE: screen or rest; the estimates made again)
    python scripts/probe_0185_area.py screen
    python scripts/probe_0185_area.py held SIGNAL...   (the entered signals)
"""
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import torch
from scipy.stats import mannwhitneyu

sys.path.insert(0, str(Path(__file__).resolve().parent))
import calibrate_intervals as ci                                          # noqa: E402
from colonbench.benchmark.evaluate import noisy                           # noqa: E402
from colonbench.completion import caltable, intervals                     # noqa: E402
from colonbench.completion.method import CompletionMethod, method_cloud, model_path, steps_version   # noqa: E402
from colonbench.completion.surface import cloud_density, triangle_areas   # noqa: E402
from colonbench.shards.reader import Shard                                 # noqa: E402

NAMES = ("area_ratio", "fold_ratio", "area_gap")
CACHE = Path("runs/probe-0185")


def table():
    path = model_path(None)
    df = ci.with_units(ci.with_sets(caltable.read(caltable.path_for(path, steps_version()), ci.SIGNALS,
                                                  ci.table_source(path))))
    return df[df["set"].isin(ci.CALIBRATED)].reset_index(drop=True)


def area_signals(method, points):
    est = method.estimate(points)
    pts = method_cloud(points)
    area = triangle_areas(est.mesh_vertices, est.mesh_faces)
    observed = (area * (~est.hole_vertices[est.mesh_faces]).mean(axis=1)).sum()
    cloud = len(pts) / max(cloud_density(pts), 1e-9)
    tube = 2 * np.pi * float(est.signals["radius_mm"]) * float(est.signals["length_mm"])
    return est.coverage, {"area_ratio": cloud / max(observed, 1e-9), "fold_ratio": area.sum() / max(tube, 1e-9),
                          "area_gap": abs(cloud / max(area.sum(), 1e-9) - est.coverage)}


def make(stage, part, parts):
    torch.set_num_threads(1)
    cal = table()
    screen = (cal["set"] == "V_real") & ~cal["hole_model"].str.endswith("+end")
    rows = cal[screen if stage == "screen" else ~screen]
    method = CompletionMethod(None)
    method.intervals = None
    keys = sorted(set(zip(rows["manifest"], rows["shard"])))[part::parts]
    out = []
    for manifest, shard in keys:
        g = rows[(rows["manifest"] == manifest) & (rows["shard"] == shard)]
        with Shard(Path("data") / manifest / shard) as s:
            for _, r in g.iterrows():
                geo = s.geometry(int(r["index"]))
                coverage, sig = area_signals(method, noisy(geo["partial_points"], float(r["noise_mm"]), 0, shard,
                                                           int(r["index"])))
                if abs(coverage - r["estimate"]) > 1e-6:
                    raise SystemExit(f"{manifest} {shard} {r['index']} {r['noise_mm']}: estimate {coverage} is not "
                                     f"the table's {r['estimate']}")
                out.append({"manifest": manifest, "shard": shard, "index": int(r["index"]),
                            "noise_mm": float(r["noise_mm"]), **sig})
        print(manifest, shard, len(out), flush=True)
    CACHE.mkdir(parents=True, exist_ok=True)
    pd.DataFrame(out).to_csv(CACHE / f"{stage}-{part}-of-{parts}.csv", index=False)


def with_signals(cal):
    sig = pd.concat([pd.read_csv(p) for p in sorted(CACHE.glob("*.csv"))], ignore_index=True)
    return cal.merge(sig, on=["manifest", "shard", "index", "noise_mm"], how="inner", validate="one_to_one")


def screen():
    cal = with_signals(table())
    rows = cal[(cal["set"] == "V_real") & ~cal["hole_model"].str.endswith("+end")]
    far = (rows["true"] - rows["estimate"]).abs() > ci.BIG
    print(f"{len(rows)} estimates without an erased end on the real validation colons, {far.sum()} far off")
    for n in NAMES:
        aucs = {}
        for colon, g in rows.groupby("cell"):
            y, x = far[g.index].to_numpy(), g[n].to_numpy()
            a = mannwhitneyu(x[y], x[~y]).statistic / (y.sum() * (~y).sum())
            aucs[colon] = round(max(a, 1 - a), 3)
        print(f"  {n}: AUC {aucs}; median far / not {rows.loc[far, n].median():.3f} / {rows.loc[~far, n].median():.3f}")


def lower_right_at_70(rows, score):
    """The lower share right over the real colons at the highest threshold catching 70 % on each."""
    far = ((rows["true"] - rows["estimate"]).abs() > ci.BIG).to_numpy()
    s = score.to_numpy()
    for t in np.unique(np.round(s, 4))[::-1]:
        flag = s > t - 1e-12
        caught, right = [], []
        for colon in sorted(rows["cell"].unique()):
            m = (rows["cell"] == colon).to_numpy()
            caught.append((flag & far & m).sum() / max((far & m).sum(), 1))
            right.append((flag & far & m).sum() / max((flag & m).sum(), 1))
        if min(caught) >= 0.70:
            return t, caught, right


def held(entered):
    cal = with_signals(table())
    assert len(cal) == len(table()), "every calibrated estimate needs the signals (make rest)"
    names = intervals.scale_features(ci.KEEP)
    x0 = ci.odds_features(cal, names)
    h = ci.by_colon(cal, ci.KEEP, intervals.LEVEL)
    real = (cal["set"] == "V_real") & ~cal["hole_model"].str.endswith("+end")
    for label, extra in (("shipped features", ()), ("with " + ", ".join(entered), tuple(entered))):
        x = np.c_[x0, cal[list(extra)].to_numpy(float)] if extra else x0
        out, colons = np.empty(len(cal)), cal["colon"].to_numpy()
        for colon in np.unique(colons):
            fit_on = colons != colon
            model = ci.fit_odds(cal[fit_on], list(names) + list(extra), x[fit_on])
            out[~fit_on] = [intervals.linear_score(model, f) for f in x[~fit_on]]
        score = pd.Series(out, index=cal.index)
        width, report = ci.review_width(h, "odds", score)
        print(f"\n[{label}] all segments at 0163's threshold ({width:.3f}): {ci.said(report)}")
        t, caught, right = lower_right_at_70(cal[real], score[real])
        print(f"  no erased end, threshold {t:.3f} catching 70 % on each real colon: caught "
              f"{[round(100 * c, 1) for c in caught]}, right {[round(100 * r, 1) for r in right]}")


if __name__ == "__main__":
    if sys.argv[1] == "make":
        make(sys.argv[2], int(sys.argv[3]), int(sys.argv[4]))
    elif sys.argv[1] == "screen":
        screen()
    elif sys.argv[1] == "held":
        held(sys.argv[2:])
