"""The whole-colon leaderboard: tables from stored ``evaluate --task colon`` runs, never edited by hand.

:func:`write_colon_leaderboard` writes, from runs on the same whole-colon data:

* ``leaderboard.md``: per noise level, every method and track ranked by
  segment coverage MAE, with the whole-colon coverage error, how the method's
  intervals held the segments' truths (where it gives them), the centerline's
  precision / recall at 2 mm and the seconds per map; then the *in-context vs
  segment-only* table: the same segments, one for one, under both tracks, on
  all segments and on those with an unobserved end, per colon source
  (procedural colons, each imported colon);
* ``leaderboard.csv``, ``leaderboard.json``: the same rows;
* ``colon-maps.png``: one colon's map, truth and error side by side
  (:func:`colonbench.reports.coverage_map.map_truth_error`).

Errors are in percentage points (estimated - true). A segment has an
*unobserved end* when less than half of the 10 mm band at one of its planes
was seen (:mod:`colonbench.benchmark.colon_metrics`).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import pandas as pd

from colonbench.benchmark.colon_evaluate import load_colon_results, scoreable
from colonbench.benchmark.summary import error_stats, failed, interval_stats, scored_errors
from colonbench.errors import InputError
from colonbench.reports.leaderboard import add_run, data_line, interval

#: Settings two whole-colon runs must share to be compared.
SAME = ("data", "noise_mm", "noise_seed", "contexts_mm", "segment_mm", "thresholds_mm")


def merge_colon_runs(run_dirs, extra=()) -> tuple[dict, pd.DataFrame, pd.DataFrame]:
    """Per-segment and per-map rows of several whole-colon runs on the same data, and what they were.

    ``extra``: runs already loaded, ``(run record, segments, colons, label)`` (the shipped reference results).
    """
    items = [(*load_colon_results(r), str(r)) for r in run_dirs] + list(extra)
    if not items:
        raise InputError("no run folders given")
    meta, segs, cols = None, [], []
    for run, s, c, label in items:
        meta = add_run(meta, run, label, items[0][3], SAME)
        segs.append(s)
        cols.append(c)
    return meta, pd.concat(segs, ignore_index=True), pd.concat(cols, ignore_index=True)


def colon_source(colon: pd.Series) -> pd.Series:
    """Each row's colon source: ``procedural`` for a generated colon (``colon-<k>``), else the imported colon's name."""
    return colon.where(~colon.str.startswith("colon-"), "procedural")


def colon_table(segments: pd.DataFrame, colons: pd.DataFrame) -> pd.DataFrame:
    """One row per noise level, method and track: segment and whole-colon errors, centerline, speed.

    Columns: ``noise_mm``, ``method``, ``track``, ``maps``, ``failed_maps``,
    ``segments``, ``estimated``, ``failed_segments`` (the method's failures in finished maps; a segment the map
    gave no method, :func:`~colonbench.benchmark.colon_evaluate.skipped_rows`, is left out), ``segment_mae`` (with its
    95 % bootstrap interval over segments, ``segment_mae_lo``, ``segment_mae_hi``), ``segment_median``,
    ``segment_bias``, ``segment_q95`` (points; a failed segment scored as the farther of coverage 0 and 1),
    ``end_unobserved``, ``end_unobserved_mae``, ``whole_mae``, ``whole_bias``
    (points; the whole coverage of a failed map, or of one with no segment estimated, scored as a failed
    segment's),
    ``interval_covered`` (% of the segments' truths inside the method's
    interval), ``interval_width`` (its mean width, points; both NaN for a method
    without intervals), ``interval_segments`` (the segments with an interval and a
    truth they are over), ``centerline_precision``, ``centerline_recall`` (means),
    ``seconds_per_map``.
    """
    from colonbench.benchmark import stats

    rows = []
    keys = ["noise_mm", "method", "track"]
    for key, c in colons.groupby(keys, sort=True):
        s = segments[(segments[keys] == pd.Series(key, index=keys)).all(axis=1)]
        ends = s["end_unobserved"].astype(bool).to_numpy()
        ok = c[c["error"] == ""]
        # a segment the method failed on: the farther of coverage 0 and 1; one the map gave no method: left out
        s = scoreable(s)
        seg_err = scored_errors(s)
        # a failed map, or one with no segment estimated (no whole-colon coverage): its whole-colon coverage scored
        # so too (stored in points); a failed map's segments were never cut
        none = c["error"].eq("") & c["coverage"].isna()
        whole = error_stats(scored_errors(c.assign(coverage_error=c["coverage_error"] / 100,
                                                   error=c["error"].where(~none, "no segment estimated"))))
        rows.append({**dict(zip(keys, key)), "maps": len(c), "failed_maps": int((c["error"] != "").sum()),
                     "segments": len(s), "estimated": int(s["coverage_error"].notna().sum()),
                     "failed_segments": int(failed(s).sum()),
                     **{f"segment_{k}": v for k, v in error_stats(seg_err).items()},
                     **{f"segment_{k}": v for k, v in stats.mae_interval(seg_err, seed=0).items() if k != "mae"},
                     "end_unobserved": int(ends.sum()),
                     "end_unobserved_mae": error_stats(seg_err[ends])["mae"],
                     "whole_mae": whole["mae"], "whole_bias": whole["bias"],
                     **interval_stats(s, failures=True),     # a failed segment: a truth outside
                     "centerline_precision": float(ok["centerline_precision"].mean()) if len(ok) else math.nan,
                     "centerline_recall": float(ok["centerline_recall"].mean()) if len(ok) else math.nan,
                     "seconds_per_map": float(ok["seconds"].mean()) if len(ok) else math.nan})
    tab = pd.DataFrame(rows)
    return tab.sort_values(["noise_mm", "segment_mae", "method", "track"], na_position="last").reset_index(drop=True)


def context_table(segments: pd.DataFrame, baseline: str = "segment-only") -> pd.DataFrame:
    """In-context vs segment-only on the same segments, one for one, per noise, method, context track and source.

    A segment counts where both tracks estimated it. Columns: ``noise_mm``,
    ``method``, ``track``, ``source`` (``procedural``, an imported colon's
    name, or ``all``), ``segments``, ``segment_only_mae``, ``context_mae``,
    ``ratio`` (context / segment-only), and the same three on the
    ``end_unobserved`` segments.
    """
    ids = ["noise_mm", "method", "shard", "index", "segment"]
    seg = segments.assign(source=colon_source(segments["colon"]))
    base = seg[seg["track"] == baseline].set_index(ids)
    rows = []
    for track in sorted(set(seg["track"]) - {baseline}):
        other = seg[seg["track"] == track].set_index(ids)
        both = base[["coverage_error", "end_unobserved", "source"]].join(
            other[["coverage_error"]].rename(columns={"coverage_error": "coverage_error_ctx"}), how="inner")
        both = both.dropna(subset=["coverage_error", "coverage_error_ctx"])
        both = both.reset_index()
        for (noise, method), g in both.groupby(["noise_mm", "method"], sort=True):
            for source, h in [("all", g)] + sorted(g.groupby("source")):
                if source == "all" and g["source"].nunique() == 1:
                    continue
                e = h[h["end_unobserved"].astype(bool)]
                a, b = error_stats(h["coverage_error"])["mae"], error_stats(h["coverage_error_ctx"])["mae"]
                ea, eb = error_stats(e["coverage_error"])["mae"], error_stats(e["coverage_error_ctx"])["mae"]
                rows.append({"noise_mm": noise, "method": method, "track": track, "source": source,
                             "segments": len(h), "segment_only_mae": a, "context_mae": b,
                             "ratio": b / a if a > 0 else math.nan, "end_unobserved": len(e),
                             "end_segment_only_mae": ea, "end_context_mae": eb,
                             "end_ratio": eb / ea if len(e) and ea > 0 else math.nan})
    return pd.DataFrame(rows)


def _f(x, digits=2) -> str:
    return "n/a" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.{digits}f}"


def _interval_cell(r) -> str:
    """``covered % of n, width`` of a method's intervals, or n/a for a method without."""
    if math.isnan(r.get("interval_covered", math.nan)):
        return "n/a"
    return f"{r['interval_covered']:.1f} % of {r['interval_segments']}, {r['interval_width']:.1f}"


def colon_markdown(meta: dict, tab: pd.DataFrame, ctx: pd.DataFrame) -> str:
    """The whole-colon leaderboard as Markdown."""
    lines = ["# colonbench whole-colon leaderboard", "",
             data_line(meta, "whole-colon reconstructions") + f" Mapped at {meta['segment_mm']:g} mm segments; "
             "segment MAE with its 95 % bootstrap interval over segments. Input noise: Gaussian, sigma in mm, seed "
             f"{meta['noise_seed']}. Coverage errors in percentage points (estimated - true): each segment against "
             "the true coverage of the same stretch of the true surface, and the whole colon's; a failed segment (and "
             "a failed map's whole colon) is scored as the farther of coverage 0 and 1; truth in interval: the "
             "share of the segments whose true coverage lies inside the method's interval (n/a for a method without), "
             "its mean width in points; centerline precision / recall at 2 mm (docs/mapping.md). Tracks: segment-only "
             "(each segment on its own points, the paper's protocol) and context-M mm (the neighbours' points up to M "
             "mm beyond each plane too).", ""]
    for noise, g in tab.groupby("noise_mm", sort=True):
        lines += [f"## Noise sigma = {noise:g} mm", "",
                  "| method | version | track | maps (failed) | segments (estimated, failed) | segment MAE [95 % CI] "
                  "| median | bias | q95 | unobserved-end segments: n, MAE | whole colon: MAE, bias | truth in "
                  "interval (of segments), width | centerline P / R | s/map |",
                  "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
        for _, r in g.iterrows():
            version = meta["methods"].get(r["method"], {}).get("version", "")
            lines.append(f"| {r['method']} | {version} | {r['track']} | {r['maps']} ({r['failed_maps']}) | "
                         f"{r['segments']} ({r['estimated']}, {r['failed_segments']}) | {_f(r['segment_mae'])} "
                         f"{interval(r['segment_mae_lo'], r['segment_mae_hi'])} | {_f(r['segment_median'])} | "
                         f"{_f(r['segment_bias'])} | {_f(r['segment_q95'])} | {r['end_unobserved']}, "
                         f"{_f(r['end_unobserved_mae'])} | {_f(r['whole_mae'])}, {_f(r['whole_bias'])} | "
                         f"{_interval_cell(r)} | {_f(r['centerline_precision'])} / {_f(r['centerline_recall'])} | "
                         f"{_f(r['seconds_per_map'], 1)} |")
        lines.append("")
    if len(ctx):
        lines += ["## In context vs segment-only, the same segments", "",
                  "Segments estimated under both tracks, one for one; ratio = in-context MAE / segment-only MAE.", "",
                  "| noise | method | track | colons | segments | segment-only MAE | in-context MAE | ratio | "
                  "unobserved-end segments | segment-only | in-context | ratio |",
                  "|---:|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
        for _, r in ctx.iterrows():
            lines.append(f"| {r['noise_mm']:g} | {r['method']} | {r['track']} | {r['source']} | {r['segments']} | "
                         f"{_f(r['segment_only_mae'])} | {_f(r['context_mae'])} | {_f(r['ratio'])} | "
                         f"{r['end_unobserved']} | {_f(r['end_segment_only_mae'])} | {_f(r['end_context_mae'])} | "
                         f"{_f(r['end_ratio'])} |")
        lines.append("")
    lines += ["Runs: " + ", ".join(f"`{r['path']}`" for r in meta["runs"]) + ".", ""]
    return "\n".join(lines)


def write_colon_leaderboard(run_dirs, out, figures: bool = True, extra=()) -> dict:
    """Write ``leaderboard.md``, ``.csv``, ``.json`` (and ``colon-maps.png``) for whole-colon runs on the same data.

    Returns
    -------
    dict
        ``{"markdown": text, "paths": [written files]}``.
    """
    meta, segments, colons = merge_colon_runs(run_dirs, extra)
    tab, ctx = colon_table(segments, colons), context_table(segments)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    text = colon_markdown(meta, tab, ctx)
    paths = [out / "leaderboard.md", out / "leaderboard.csv", out / "leaderboard.json"]
    paths[0].write_text(text)
    tab.to_csv(paths[1], index=False)
    paths[2].write_text(json.dumps({"task": "colon", **{k: meta[k] for k in SAME}, "suite": meta["suite"],
                                    "methods": meta["methods"],
                                    "runs": meta["runs"], "rows": json.loads(tab.to_json(orient="records")),
                                    "in_context": json.loads(ctx.to_json(orient="records"))}, indent=1))
    if figures:
        from colonbench.reports.coverage_map import map_truth_error

        for r in meta["runs"]:
            examples = sorted((Path(r["path"]) / "examples").glob("*.pkl"))
            if examples:
                paths.append(map_truth_error(examples[0], out / "colon-maps.png"))
                break
    return {"markdown": text, "paths": paths}
