"""Decision record 0175's probe (one-off, removed after): how much of a ring each end's cut rim fills, against the
estimates off by more than 15 points, on the calibration's estimates without noise.

Run from the repository root after ``python scripts/calibrate_intervals.py`` has cached its estimates (about 6
minutes on 2 cores): ``python scripts/probe_0175_fill.py``.
"""
import sys
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))
import calibrate_intervals as ci  # noqa: E402
from colonbench.completion import calfile, planes  # noqa: E402
from colonbench.completion.method import CompletionMethod, model_path  # noqa: E402
from colonbench.shards.reader import Shard  # noqa: E402

parts = []
for name, s in ci.MANIFESTS.items():
    p = pd.read_csv(Path("data") / name / "completion-estimates-6d813b3c4351-steps=10-signals4.csv")
    p = p.assign(manifest=name, set=s)
    if name == "calibration":
        p.loc[p.colon_id >= ci.REAL_IDS, "set"] = "train_real"
    parts.append(p)
df = ci.with_units(pd.concat(parts, ignore_index=True))
df = df[(df.noise_mm == 0) & df.set.isin(ci.CALIBRATED)]
cal = calfile.load(model_path(None), None)
lh = np.array([cal.interval(e, s) for e, s in zip(df.estimate, ci.signals(df))])
df["inside"] = (lh[:, 0] - 1e-12 <= df.true) & (df.true <= lh[:, 1] + 1e-12)

record = []
original = planes._rim_plane


def recorded(point, normal, x, band, cap_deg, min_share):
    """The rim search, recording the sectors the accepted rim fills (0 where none)."""
    out = original(point, normal, x, band, cap_deg, min_share)
    plane = out[0] if isinstance(out, tuple) and isinstance(out[1], int) else out   # after 0175: (plane, sectors)
    if plane is None:
        record.append(0)
        return out
    outward = -plane[1]
    near = planes._touching(x, outward, band) if plane[0] is not point else \
        x[np.abs((x - point) @ -normal - ((x - point) @ -normal).max()) < band]
    record.append(int(planes._sectors(near - point, outward[None], np.ones((1, len(near)), bool))[0]))
    return out


planes._rim_plane = recorded
method = CompletionMethod(None)
method.intervals = None
fill = []
for _, r in df.iterrows():
    with Shard(Path("data") / r.manifest / r.shard) as shard:
        geo = shard.geometry(int(r["index"]))
    record.clear()
    method.estimate(ci.noisy(geo["partial_points"], 0.0, 0, r.shard, int(r["index"])))
    fill.append(min(record[-2:]) / planes.RIM_SECTORS if len(record) >= 2 else 0.0)
df["fill"] = fill
df["far"] = (df.estimate - df.true).abs() > 0.15
df["band"] = pd.cut(df.fill, [-0.01, 0.55, 0.75, 0.9, 1.0])
print(df.groupby(["cell", "band"], observed=True).agg(n=("far", "size"), far=("far", "mean"),
                                                      inside=("inside", "mean")).round(3).to_string())
far = df[df.far & (df.set == "V_real")]
print(f"the real colons' estimates off by more than 15 points: {len(far)}; by hole model, with their median fill:")
print(far.groupby("hole_model").agg(n=("fill", "size"), fill=("fill", "median")).round(3).to_string())
