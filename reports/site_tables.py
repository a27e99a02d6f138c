"""The tables of a suite's page on the leaderboard site (:mod:`colonbench.reports.site`), and its chart's rows.

Each table is sized for a 1280 px window: a method's version string is on its
method page, not in the tables; the interval and review scores are a table of
their own, as are precision and recall; the table of every statistic lists
the statistics down the page, a few methods across. Every string from a run is
escaped (:mod:`colonbench.reports.webpage`).
"""

from __future__ import annotations

import re
from pathlib import Path

import pandas as pd

from colonbench.benchmark.summary import REVIEW_OFF
from colonbench.reports import leaderboard
from colonbench.reports.webpage import esc, fmt, interval_cell, slug, table

#: Precision / recall statistics, shown in their own table rather than the main one.
PR_COLUMN = re.compile(r"^(holes|centerline)_(precision|recall)_(.+)_(mean|median|q25|q75|undefined)$")
#: The scores of a method's coverage intervals and its review flags, shown in their own table.
INTERVAL_COLUMN = re.compile(r"^(interval|review)_")
#: Columns that lead the main table where present, in this order; the others follow in the frame's order.
FIRST = ("track", "segments", "maps", "failed", "failed_maps", "failed_segments", "coverage_undefined",
         "coverage_mae", "segment_mae", "vs_baseline")
#: Columns no table of the page shows: the noise level is the section, the version is on the method's page, the
#: others are in other cells (``source``: the page's own column says where a row came from).
HIDDEN = {"noise_mm", "method", "version", "reference", "baseline", "vs_baseline_pairs", "source"}
LABELS = {"coverage_undefined": "undefined", "coverage_mae": "MAE [95 % CI]", "segment_mae": "segment MAE [95 % CI]",
          "vs_baseline": "Δ vs best baseline [95 % CI]", "coverage_median": "median", "coverage_bias": "bias",
          "coverage_q95": "q95", "interval_covered": "truth in interval, %", "interval_width": "interval width",
          "interval_segments": "segments with an interval", "seconds": "s/segment", "seconds_per_map": "s/map",
          "takes_length": "takes the length", "review_flagged": "flagged for review, %",
          "review_recall": "review recall, %", "review_precision": "review precision, %",
          "review_off": f"off by over {100 * REVIEW_OFF:g} percentage points"}
#: Methods per column group of the table of every statistic (so that it fits the window).
EVERY_METHODS = 8


def source(rec: dict) -> str:
    """``shipped``, ``submitted`` or ``mine``: where a method's rows came from (:func:`leaderboard.source
    <colonbench.reports.leaderboard.source>`, a run given here read as ``mine``)."""
    got = leaderboard.source(rec)
    return got if got in ("shipped", "submitted") else "mine"


def marks(m: str, methods: dict) -> str:
    """A method's marks after its name (:func:`leaderboard.marks <colonbench.reports.leaderboard.marks>`)."""
    return leaderboard.marks(methods.get(m, {}))


def method_cell(m: str, methods: dict, root: str) -> tuple[str, str]:
    """A method's name linked to its page, with its marks; sorted by the name."""
    return f'<a href="{root}methods/{esc(slug(m))}.html">{esc(m)}</a>{marks(m, methods)}', m


def row_attrs(m: str, methods: dict) -> dict:
    """A method's row: ``data-method``, and its source as the class (``mine`` rows are shaded)."""
    return {"data-method": m, "class": source(methods.get(m, {}))}


def chart_rows(mae: pd.DataFrame, methods: dict, root: str) -> pd.DataFrame:
    """Headline rows (:func:`colonbench.reports.site.headline`) ranked as the index ranks them (references last,
    then by the mean MAE over noise levels), with the ``label``, ``href`` and ``kind`` the chart draws."""
    order = mae.groupby("method")["mae"].mean().reset_index()
    order["reference"] = order["method"].map(lambda m: bool(methods.get(m, {}).get("reference")))
    ranked = list(order.sort_values(["reference", "mae", "method"], na_position="last")["method"])
    out = mae.assign(rank=mae["method"].map(ranked.index)).sort_values(["rank", "noise_mm"]).drop(columns="rank")
    return out.assign(
        label=[m + marks(m, methods) for m in out["method"]],
        href=[f"{root}methods/{slug(m)}.html" for m in out["method"]],
        kind=["reference" if methods.get(m, {}).get("reference") else
              "mine" if source(methods.get(m, {})) == "mine" else "other" for m in out["method"]])


def _cells(g: pd.DataFrame, cols: list[str]) -> tuple[list, list]:
    heads = [(LABELS.get(c, c.replace("_", " ")), g[c].dtype.kind in "ifb" or f"{c}_lo" in g.columns) for c in cols]
    rows = [[interval_cell(r, c) if f"{c}_lo" in g.columns else
             (lambda t: (esc(t[0]), t[1]))(fmt(r[c], c)) for c in cols] for _, r in g.iterrows()]
    return heads, rows


def main_table(tid: str, g: pd.DataFrame, methods: dict, root: str) -> str:
    """The leaderboard frame ``g`` (one noise level) but precision / recall and the interval and review scores,
    intervals merged into their value's cell."""
    cols = [c for c in g.columns if c not in HIDDEN and not PR_COLUMN.match(c) and not INTERVAL_COLUMN.match(c)
            and not (c.endswith(("_lo", "_hi")) and c[:-3] in g.columns)]
    cols = [c for c in FIRST if c in cols] + [c for c in cols if c not in FIRST]
    heads, cells = _cells(g, cols)
    rows = []
    for (_, r), rest in zip(g.iterrows(), cells):
        rec = methods.get(r["method"], {})
        run = str(rec.get("run", ""))
        src = source(rec) if source(rec) != "mine" else "/".join(Path(run).parts[-2:])
        rows.append((row_attrs(r["method"], methods), [
            method_cell(r["method"], methods, root), (f'<span title="{esc(run)}">{esc(src)}</span>', src)] + rest))
    return table(tid, [("method", False), ("source", False)] + heads, rows)


def interval_table(tid: str, g: pd.DataFrame, methods: dict, root: str) -> str:
    """The scores of the methods' coverage intervals and review flags; empty where the frame has none or no method
    gives either."""
    cols = [c for c in g.columns if INTERVAL_COLUMN.match(c) and c not in HIDDEN]
    if not cols or g[[c for c in cols if c not in ("interval_segments", "review_off")]].isna().all(axis=None):
        return ""
    heads, cells = _cells(g, cols)
    rows = [(row_attrs(r["method"], methods), [method_cell(r["method"], methods, root)] + rest)
            for (_, r), rest in zip(g.iterrows(), cells)]
    return ("<h3>Intervals and review: truth inside the method's interval and its width (percentage points); the "
            "estimates it flags for review</h3>" + table(tid, [("method", False)] + heads, rows))


def pr_table(tid: str, g: pd.DataFrame, methods: dict, root: str) -> str:
    """Precision and recall, mean (median), per threshold; empty where the frame has none."""
    cols = [c for c in g.columns if PR_COLUMN.match(c) and c.endswith("_mean")]
    if not cols:
        return ""
    heads = [("method", False)] + [(re.sub(r"^(\w+?)_(precision|recall)_(.+)_mean$",
                                           lambda m: f"{m[1]} {m[2][0].upper()} @{m[3]}", c), True) for c in cols]
    rows = [(row_attrs(r["method"], methods), [method_cell(r["method"], methods, root)] + [
        (esc(f"{fmt(r[c])[0]} ({fmt(r[c[:-5] + '_median'])[0]})"), fmt(r[c])[1]) for c in cols])
        for _, r in g.iterrows()]
    return "<h3>Holes and centerline: precision (P) and recall (R), mean (median)</h3>" + table(tid, heads, rows)


def breakdown_tables(bd: pd.DataFrame, methods: dict, root: str) -> str:
    """Per grouping and noise level, methods x groups: MAE [95 % CI] (segments), as breakdowns.md."""
    parts = []
    for by, g in bd.groupby("by", sort=False):
        for noise in [None] if by == "noise_mm" else sorted(g["noise_mm"].unique()):
            h = g if noise is None else g[g["noise_mm"] == noise]
            names = sorted(h["group"].astype(str).unique(), key=lambda x: (len(x), x))
            rows = []
            for m, r in h.groupby("method", sort=True):
                cells = {}
                for _, x in r.iterrows():
                    text, v = interval_cell(x, "mae")
                    cells[str(x["group"])] = (f"{text} ({esc(x['segments'])})", v)
                rows.append((row_attrs(m, methods), [method_cell(m, methods, root)] + [cells.get(c, ("", ""))
                                                                                      for c in names]))
            title = f"By {by.replace('_', ' ')}" + ("" if noise is None else f", noise {noise:g} mm")
            tid = f"breakdown-{by}-{'all' if noise is None else f'{noise:g}'}"
            parts.append(f"<h3>{esc(title)}</h3>" + table(tid, [("method", False)] + [(c, True) for c in names], rows))
    return "\n".join(parts)


def every_tables(tab: pd.DataFrame, methods: dict, root: str) -> str:
    """Every statistic of the leaderboard table as computed (leaderboard.csv, less the versions): per noise level,
    the statistics down and at most :data:`EVERY_METHODS` methods across."""
    stats = [c for c in tab.columns if c not in ("noise_mm", "method", "version")]
    parts = []
    for noise, h in tab.groupby("noise_mm", sort=True):
        h = h.reset_index(drop=True)
        for k in range(0, len(h), EVERY_METHODS):
            part = h.iloc[k:k + EVERY_METHODS]
            heads = [("statistic", False)] + [(m + marks(m, methods), True) for m in part["method"]]
            rows = [({"data-statistic": c}, [(esc(c), c)] + [
                (lambda t: (esc(t[0]), t[1]))(fmt(v, c)) for v in part[c]]) for c in stats]
            tid = f"every-noise{noise:g}" + (f"-{k // EVERY_METHODS + 1}" if len(h) > EVERY_METHODS else "")
            parts.append(f"<h3>Noise sigma = {noise:g} mm</h3>" + table(tid, heads, rows))
    return "\n".join(parts)
