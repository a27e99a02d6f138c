"""The README's results table and docs/method.md's accuracy and intervals tables, made from the shipped reference
results (never typed by hand); tests/test_docs.py checks that the docs hold them.

    python scripts/results_table.py              # the results table (README.md)
    python scripts/results_table.py --accuracy   # completion against its exact-heatmap bound per suite (docs/method.md)
    python scripts/results_table.py --intervals  # completion's intervals and review per suite (docs/method.md)
"""

from __future__ import annotations

import math
import textwrap

import numpy as np

from colonbench.benchmark import shipped, suites, tracks
from colonbench.benchmark.registry import BASELINES
from colonbench.benchmark.summary import interval_stats, review_stats, scored_errors

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
        from colonbench.benchmark.colon_evaluate import scoreable

        segs = scoreable(segs[segs["track"] == suite.headline_track])   # the map's skipped segments left out
    return _mae_by(segs)


def _mae_by(segs) -> dict:
    """``{(method, noise): MAE in points}`` of result rows, failed segments scored as every table scores them."""
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

    lines = ["| coverage MAE, percentage points (noiseless / 0.5 mm) | " + " | ".join(s.id for s in chosen) + " |",
             "|---|" + "---:|" * len(chosen)]
    for row in ROWS:
        lines.append(f"| {LABELS.get(row, row)} | " + " | ".join(cell(s.id, row) for s in chosen) + " |")
    return "\n".join(lines + elsewhere(chosen))


def elsewhere(chosen) -> list[str]:
    """A line under the table naming the rows made on data within tolerance of the published data (decision record
    0327), where there are any."""
    made = {}
    for s in chosen:
        for row in ROWS:
            m, _, track = row.partition("@")
            if s.task != "colon" and shipped.own_data(s, m, track or tracks.DEFAULT):
                made.setdefault(m, {}).setdefault(s.id, []).append(track or tracks.DEFAULT)
    if not made:
        return []
    def tracks_of(on) -> str:
        return "both tracks" if len(on) == len(tracks.TRACKS) else f"the {' and '.join(on)} track"

    def rows_of(m, ids) -> str:
        if len({tuple(on) for on in ids.values()}) == 1:
            return f"{m}'s rows of {', '.join(ids)}, {tracks_of(next(iter(ids.values())))}"
        return f"{m}'s rows of " + ", ".join(f"{sid} ({tracks_of(on)})" for sid, on in ids.items())

    said = "; ".join(rows_of(m, ids) for m, ids in made.items())
    return [""] + textwrap.wrap(f"Made on data within tolerance of the published data "
                                f"([why](docs/benchmark.md#suite-versions)): {said}.", 120, break_on_hyphens=False)


#: The segment suites of docs/method.md's accuracy table, each with what it tests.
ACCURACY = {"paper-v1": "", "wide-v1": "", "real-v1": ", a real colon no model trained on",
            "video-v1": ", reconstruction-like partials"}


def accuracy_table() -> str:
    """Completion's coverage MAE beside the exact heatmap's (``gt-heatmap``, the bound of its post-processing) and
    its centerline's precision / recall at 2 mm, per suite of :data:`ACCURACY` (noiseless / 0.5 mm), and the widened
    suite's MAE without its segments whose end was never seen (a hole model ``...+end``)."""
    lines = ["| suite | completion | gt-heatmap | completion centerline P / R @2 mm (noiseless) |", "|---|---|---|---|"]

    def pair(maes, method) -> str:
        return f"{maes[(method, 0.0)]:.2f} / {maes[(method, 0.5)]:.2f}"

    mine = {}
    for sid, what in ACCURACY.items():
        segs = shipped.load(suites.get(sid))[1]
        mine[sid] = segs[segs["method"] == "completion"]
        clean = mine[sid][mine[sid]["noise_mm"] == 0.0]
        maes = _mae_by(segs)
        lines.append(f"| `{sid}` ({len(clean)}{what}) | {pair(maes, 'completion')} | {pair(maes, 'gt-heatmap')} | "
                     f"{clean['centerline_precision_2mm'].mean():.2f} / {clean['centerline_recall_2mm'].mean():.2f} |")
    end = mine["wide-v1"]["hole_model"].str.endswith("+end")
    unseen = int((end & (mine["wide-v1"]["noise_mm"] == 0.0)).sum())
    without = pair(_mae_by(mine["wide-v1"][~end]), "completion")
    return "\n".join(lines + ["", f"Without the widened suite's {unseen} segments whose end was never seen, "
                               f"completion's MAE is {without}."])


def interval_table(method: str = "completion") -> str:
    """Per segment suite and track: the share of truths inside the method's intervals, their mean width, the share
    flagged for review, the share of the estimates off by more than 15 points it flags and the share of its flags
    that are (noiseless / 0.5 mm)."""
    lines = ["| suite | truth inside the 90 % interval | mean width, points | flagged for review | off by > 15 points: "
             "flagged | flags off by > 15 points |", "|---|---:|---:|---:|---:|---:|"]
    for suite in suites.latest().values():
        for track in tracks.TRACKS:
            item = shipped.load(suite, track=track) if suite.task != "colon" else None
            if item is None:
                continue
            rows = item[1][item[1]["method"] == method]
            st = {n: {**interval_stats(g, failures=True), **review_stats(g)} for n, g in rows.groupby("noise_mm")}

            def pair(key, digits=1, unit=" %"):
                got = [st[n][key] for n in (0.0, 0.5)]
                return "n/a" if all(v != v for v in got) else \
                    " / ".join(f"{v:.{digits}f}" if v == v else "n/a" for v in got) + unit

            name = suite.id + ("" if track == tracks.DEFAULT else ", length known")
            lines.append(f"| `{name}` | {pair('interval_covered')} | {pair('interval_width', 0, '')} | "
                         f"{pair('review_flagged', 0)} | {pair('review_recall', 0)} | {pair('review_precision', 0)} |")
    return "\n".join(lines)


if __name__ == "__main__":
    import argparse

    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    which = ap.add_mutually_exclusive_group()
    which.add_argument("--accuracy", action="store_true", help="docs/method.md's accuracy table")
    which.add_argument("--intervals", action="store_true", help="docs/method.md's intervals table")
    args = ap.parse_args()
    print(interval_table() if args.intervals else accuracy_table() if args.accuracy else tables())
