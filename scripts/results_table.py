"""The README's results table, made from the shipped reference results (never typed by hand).

    python scripts/results_table.py      # prints the Markdown table; tests/test_docs.py checks the README holds it
"""

from __future__ import annotations

import math

from colonbench.benchmark import shipped, suites
from colonbench.benchmark.registry import BASELINES

#: The rows of the README's table: the paper's method, its baselines, the classical reference and the constant guess.
ROWS = ("completion",) + BASELINES + ("poisson", "constant")


def _maes(suite) -> dict:
    """``{(method, noise): MAE in points}`` of a suite's shipped results (the in-context track of a whole-colon
    suite)."""
    item = shipped.load(suite)
    if item is None:
        return {}
    segs = item[1]
    if suite.headline_track is not None:
        segs = segs[segs["track"] == suite.headline_track]
    return {(m, n): 100 * g["coverage_error"].abs().mean() for (m, n), g in segs.groupby(["method", "noise_mm"])}


def tables() -> str:
    chosen = list(suites.latest().values())
    maes = {s.id: _maes(s) for s in chosen}

    def cell(sid, m):
        a, b = maes[sid].get((m, 0.0), math.nan), maes[sid].get((m, 0.5), math.nan)
        return "—" if math.isnan(a) else f"{a:.1f} / {b:.1f}"

    lines = ["| coverage MAE, points (noiseless / 0.5 mm) | " + " | ".join(s.id for s in chosen) + " |",
             "|---|" + "---:|" * len(chosen)]
    for m in ROWS:
        lines.append(f"| {m} | " + " | ".join(cell(s.id, m) for s in chosen) + " |")
    return "\n".join(lines)


if __name__ == "__main__":
    print(tables())
