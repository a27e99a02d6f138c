"""Decision record 0169's probe (a one-off): the shipped calibration on sixteen more paper-like colons.

    python scripts/probe_0169_more_paper_colons.py [--data data]
"""

from __future__ import annotations

import argparse
import importlib.util
from pathlib import Path

import numpy as np
import yaml

from colonbench.completion import intervals
from colonbench.completion.method import CompletionMethod, model_path, steps_version
from colonbench.shards.dataset import generate
from colonbench.shards.schema import sha256_file

HERE = Path(__file__).resolve().parent
spec = importlib.util.spec_from_file_location("calibrate_intervals", HERE / "calibrate_intervals.py")
ci = importlib.util.module_from_spec(spec)
spec.loader.exec_module(ci)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", default="data")
    args = ap.parse_args()
    raw = yaml.safe_load((ci.ROOT / "calibration-paper.yaml").read_text())
    raw["name"] = "probe-0169-paper"
    raw["description"] = "Decision record 0169's probe: paper.yaml's validation colons 424-439"
    raw["splits"] = {"validation": {"colons": {"first": 424, "count": 16}, "segments_per_length": 3,
                                    "permutations": 2, "hole_models": {"camera": 0.5, "spheres": 0.5},
                                    "noise_mm": {0.0: 1.0}}}
    manifest = Path(args.data) / "probe-0169-paper.yaml"
    manifest.parent.mkdir(parents=True, exist_ok=True)
    manifest.write_text(yaml.safe_dump(raw, sort_keys=False))
    folder = Path(args.data) / "probe-0169-paper"
    generate(manifest, folder, workers=2, splits=["validation"], progress=False)
    method = CompletionMethod(None)
    method.intervals, method.spread, method.hole_depth, method.misfit = None, True, True, True
    path = model_path(None)
    cache = folder / f"completion-estimates-{sha256_file(path)[:12]}-{steps_version()}-signals4.csv"
    df = ci.estimates(folder, method, cache)
    cal = intervals.load(path, steps_version())
    print("calibration", cal.source["id"], "colons", sorted(df["colon_id"].unique()))
    lo_hi = np.array([cal.interval(e, ci.signals_of(r)) for e, (_, r) in zip(df["estimate"], df.iterrows())])
    df["inside"] = (lo_hi[:, 0] - 1e-12 <= df["true"]) & (df["true"] <= lo_hi[:, 1] + 1e-12)
    df["width"] = 100 * (lo_hi[:, 1] - lo_hi[:, 0])
    df["over10"] = df["estimate"] - df["true"] > 0.10
    for keys in (["noise_mm"], ["hole_model", "noise_mm"]):
        print(df.groupby(keys).agg(n=("inside", "size"), inside=("inside", "mean"), width=("width", "mean"),
                                   over10=("over10", "mean")).assign(inside=lambda d: (100 * d["inside"]).round(1),
                                                                     over10=lambda d: (100 * d["over10"]).round(1),
                                                                     width=lambda d: d["width"].round(1)).to_string())


if __name__ == "__main__":
    main()
