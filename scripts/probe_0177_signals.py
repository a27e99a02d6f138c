"""Decision record 0177's probe (one-off, removed after): the signals' medians of the real validation colons'
estimates off by more than 15 points and of the others, on the segments without an erased end (decision record 0176).

Run from the repository root after ``python scripts/calibrate_intervals.py`` has cached its estimates (seconds):
``python scripts/probe_0177_signals.py``.
"""
import sys
from pathlib import Path

import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))
import calibrate_intervals as ci  # noqa: E402
from colonbench.completion.method import CompletionMethod, model_path  # noqa: E402

df = ci.with_units(ci.table([(n, Path("data") / n) for n in ci.MANIFESTS], CompletionMethod(None), model_path(None)))
real = df[(df["set"] == "V_real") & ~df["hole_model"].str.endswith("+end")].copy()
real["far"] = (real["true"] - real["estimate"]).abs() > ci.BIG
cols = ["estimate", "length_mm", "span_mm", "gap_share", "hole_depth_mm", "wall_misfit_mm", "spread", "rim_fill"]
pd.set_option("display.width", 200)
print(real.groupby(["cell", "far"])[cols].median().round(3).to_string())
print(real.groupby(["cell", "far"]).size().to_string())
