"""The README's results table, made from the shipped reference results (never typed by hand).

    python scripts/results_table.py      # prints the Markdown table; tests/test_docs.py checks the README holds it
"""

from __future__ import annotations

import math

import numpy as np

from colonbench.benchmark import shipped, suites, tracks
from colonbench.benchmark.registry import BASELINES
from colonbench.benchmark.summary import scored_errors

#: The rows of the README's table: the paper's method, its baselines, the classical reference and the constant guess;
#: then the paper's method on the known-length track (``method@track``).
ROWS = ("completion",) + BASELINES + ("poisson", "constant", "completion@length")
#: How a row on another track than the points-only one is named.
LABELS = {"completion@length": "completion, length known"}


def _maes(suite, track: str = tracks.DEFAULT) -> dict:
    """``{(method, noise): MAE in points}`` of a suite's shipped results on a track (the in-context map track of a
    whole-colon suite), failed segments scored as every table scores them (docs/benchmark.md, Failures)."""
    if suite.task == "colon" and track != tracks.DEFAULT:
        return {}
    item = shipped.load(suite, track=track)
    if item is None:
        return {}
    segs = item[1]
    if suite.headline_track is not None:
        segs = segs[segs["track"] == suite.headline_track]
    return {(m, n): 100 * float(np.nanmean(np.abs(scored_errors(g))))
            for (m, n), g in segs.groupby(["method", "noise_mm"])}


def tables() -> str:
    chosen = list(suites.latest().values())
    maes = {(s.id, t): _maes(s, t) for s in chosen for t in tracks.TRACKS}

    def cell(sid, row):
        m, _, track = row.partition("@")
        got = maes[(sid, track or tracks.DEFAULT)]
        a, b = got.get((m, 0.0), math.nan), got.get((m, 0.5), math.nan)
        return "—" if math.isnan(a) else f"{a:.1f} / {b:.1f}"

    lines = ["| coverage MAE, points (noiseless / 0.5 mm) | " + " | ".join(s.id for s in chosen) + " |",
             "|---|" + "---:|" * len(chosen)]
    for row in ROWS:
        lines.append(f"| {LABELS.get(row, row)} | " + " | ".join(cell(s.id, row) for s in chosen) + " |")
    return "\n".join(lines)


if __name__ == "__main__":
    print(tables())
