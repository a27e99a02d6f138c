"""The cross-suite leaderboard of ``colonbench benchmark``: methods x suites, rebuilt from runs and shipped results.

For each suite, :func:`write_report` writes the suite's own leaderboard
(``suites/<suite id>/``: :func:`colonbench.reports.leaderboard.write_leaderboard`
with the shipped results merged in), then one summary across suites:

* ``leaderboard.md``: per noise level a table, one row per method and one
  column per suite, each cell the coverage MAE in points with its 95 %
  bootstrap interval; a whole-colon suite's cell is the segment MAE of its
  in-context track (what ``colonbench map`` reports); a segment a method
  failed on is in the MAE, scored as the farther of coverage 0 and 1, and the
  cell says how many failed; a missing cell is shown as missing, never
  averaged over; methods ranked by their mean MAE over the suites;
* ``leaderboard.csv``: one row per suite, noise level and method (``mae``,
  ``mae_lo``, ``mae_hi``, ``segments``, ``failed``, ``version``,
  ``reference``, ``source``: ``shipped``, ``submitted`` or the run folder);
* ``leaderboard.json``: the same rows with each suite's id, content hash and
  whether the data was verified, the track, and the submitted results left
  out (``notes``).

Beside the shipped results, the submitted ones of the same suite and track join
(:mod:`colonbench.benchmark.submitted`, marked ‡), less any whose name a method
of the user's runs (or a shipped one) has: the tables say which were left out.

One report is of one track (:mod:`colonbench.benchmark.tracks`): on the
known-length track the shipped results merged are that track's, and the
whole-colon suite, which has no such track, is left out.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import pandas as pd

from colonbench.benchmark import tracks
from colonbench.errors import InputError
from colonbench.reports.leaderboard import source

SUMMARY_COLUMNS = ["suite", "noise_mm", "method", "version", "reference", "mae", "mae_lo", "mae_hi", "segments",
                   "failed", "source"]


def _rows(suite, folder: Path) -> tuple[list[dict], dict]:
    """Summary rows of one suite's leaderboard folder, and its suite record."""
    lb = json.loads((folder / "leaderboard.json").read_text())
    tab = pd.read_csv(folder / "leaderboard.csv")
    methods = lb["methods"]
    rows = []
    if suite.task == "colon":
        tab = tab[tab["track"] == suite.headline_track]
        for _, r in tab.iterrows():
            rows.append({"noise_mm": r["noise_mm"], "method": r["method"], "mae": r["segment_mae"],
                         "mae_lo": r["segment_mae_lo"], "mae_hi": r["segment_mae_hi"], "segments": r["segments"],
                         "failed": r["failed_maps"] + r.get("failed_segments", 0)})
    else:
        for _, r in tab.iterrows():
            rows.append({"noise_mm": r["noise_mm"], "method": r["method"], "mae": r["coverage_mae"],
                         "mae_lo": r["coverage_mae_lo"], "mae_hi": r["coverage_mae_hi"], "segments": r["segments"],
                         "failed": r["failed"]})
    for row in rows:
        rec = methods.get(row["method"], {})
        row.update(suite=suite.id, version=rec.get("version", ""), reference=bool(rec.get("reference", False)),
                   source=source(rec))
    return rows, lb.get("suite") or {}


def write_report(out, chosen, runs: dict, shipped: bool = True, figures: bool = True,
                 track: str = tracks.DEFAULT, submitted: bool = True) -> dict:
    """Per-suite leaderboards and the cross-suite summary under ``out``, of one track.

    Parameters
    ----------
    out : path
    chosen : list of Suite
    runs : dict
        ``{suite id: run folder}`` of the methods evaluated (a suite may have none: shipped results only).
    shipped, figures : bool
    track : str
        The runs' track; the shipped (and submitted) results of that track are merged.
    submitted : bool
        Merge the submitted results (:mod:`colonbench.benchmark.submitted`) where the shipped ones may be.

    Returns
    -------
    dict
        ``summary`` (DataFrame, :data:`SUMMARY_COLUMNS`), ``markdown``, ``paths``.
    """
    from colonbench.benchmark.runfolder import read_run
    from colonbench.benchmark.submitted import leaderboard_items
    from colonbench.reports.leaderboard import write_leaderboard

    out = Path(out)
    rows, records, paths, skipped, no_length, notes = [], {}, [], [], set(), {}
    for suite in chosen:
        run_dir = runs.get(suite.id)
        mine = read_run(run_dir) if run_dir is not None else None
        extra, left_out = [], []
        if (shipped or submitted) and (mine is None or (mine.get("suite") or {}).get("verified")):
            extra, left_out = leaderboard_items(suite, track, mine=mine["methods"] if mine else (), shipped=shipped,
                                                submitted=submitted)
        if mine is None and not extra:
            skipped.append(suite.id)
            continue
        folder = out / "suites" / suite.id
        notes[suite.id] = left_out
        res = write_leaderboard([run_dir] if run_dir is not None else [], folder, figures=figures, extra=extra,
                                notes=left_out)
        paths += res["paths"]
        suite_rows, records[suite.id] = _rows(suite, folder)
        lb = json.loads((folder / "leaderboard.json").read_text())
        no_length |= {m for m, rec in lb["methods"].items() if rec.get("takes_length") is False}
        rows += suite_rows
    if not rows:
        raise InputError(f"nothing to show for {', '.join(s.id for s in chosen)}: no methods were evaluated and no "
                         "shipped results match these suites")
    summary = pd.DataFrame(rows, columns=SUMMARY_COLUMNS)
    text = markdown(summary, chosen, records, skipped, track, sorted(no_length), notes)
    out.mkdir(parents=True, exist_ok=True)
    (out / "leaderboard.md").write_text(text)
    summary.to_csv(out / "leaderboard.csv", index=False)
    suites_ = {s.id: {**records.get(s.id, {}), "tests": s.tests, "samples": s.samples} for s in chosen
               if s.id in records}
    (out / "leaderboard.json").write_text(json.dumps(
        {"track": track, "suites": suites_, "rows": json.loads(summary.to_json(orient="records")),
         "notes": {k: v for k, v in notes.items() if v}}, indent=1))
    paths += [out / "leaderboard.md", out / "leaderboard.csv", out / "leaderboard.json"]
    return {"summary": summary, "markdown": text, "paths": paths}


def _cell(r) -> str:
    """A table cell: the MAE with its interval, and how many samples failed where any did."""
    if r is None:
        return "—"
    n = 0 if pd.isna(r["failed"]) else int(r["failed"])
    failed = f" ({n} failed)" if n else ""
    if math.isnan(r["mae"]):
        return "—" + failed
    ci = "" if math.isnan(r["mae_lo"]) else f" [{r['mae_lo']:.2f}, {r['mae_hi']:.2f}]"
    return f"{r['mae']:.2f}{ci}{failed}"


def markdown(summary: pd.DataFrame, chosen, records: dict, skipped: list[str], track: str = tracks.DEFAULT,
             no_length=(), notes=None) -> str:
    """The cross-suite leaderboard as Markdown (``no_length``: the methods that took no length, on that track;
    ``notes``: per suite id, the submitted results left out and why)."""
    from colonbench.reports.leaderboard import suite_state

    ids = [s.id for s in chosen if s.id in records]
    lines = ["# colonbench benchmark" + ("" if track == tracks.DEFAULT else f", {tracks.label(track)}"), ""]
    if track != tracks.DEFAULT:
        lines += ["Each method that takes it (an `estimate` with `length_mm`, or an `exec:` program, called with "
                  "`--length-mm`) is given each segment's nominal arc length; one that takes none answers as on the "
                  "points-only track. These results compare only with the same track's. The whole-colon suite has "
                  "no such track: its map cuts the segments and knows their planes itself.", "",
                  "Took no length: " + (", ".join(f"`{m}`" for m in no_length) or "none") + ".", ""]
    lines += [
             "Coverage MAE in percentage points with its 95 % bootstrap interval over segments, per suite; a "
             "whole-colon suite's cell is the segment MAE of its in-context track. A segment a method failed on is "
             "scored as the farther of coverage 0 and 1 (an error of max(true, 1 - true), never better than an "
             "answer), and the cell says how many failed (for a whole-colon suite: its segments and whole maps). "
             "Rows marked * are references given ground truth (or the constant guess); rows marked † come from the "
             "shipped reference results. "
             "Each suite's own page (suites/<suite>/leaderboard.md) has medians, bias, q95, holes and centerline "
             "precision / recall, the paired difference against the best baseline and the breakdowns.", ""]
    for noise, g in summary.groupby("noise_mm", sort=True):
        keyed = {(r["method"], r["suite"]): r for _, r in g.iterrows()}
        order = g.groupby("method").agg(reference=("reference", "max"), mae=("mae", "mean")).reset_index()
        order = order.sort_values(["reference", "mae", "method"])
        lines += [f"## Noise sigma = {noise:g} mm", "", "| method | version | " + " | ".join(ids) + " |",
                  "|---|---|" + "---:|" * len(ids)]
        for _, o in order.iterrows():
            m = o["method"]
            first = next(keyed[(m, s)] for s in ids if (m, s) in keyed)
            mark = (" *" if first["reference"] else "") + (" †" if first["source"] == "shipped" else "") + (
                " ‡" if first["source"] == "submitted" else "")
            lines.append(f"| {m}{mark} | {first['version']} | "
                         + " | ".join(_cell(keyed.get((m, s))) for s in ids) + " |")
        lines.append("")
    lines += ["Suites (cite a suite by its id and signature" + ("" if track == tracks.DEFAULT else ", and the track")
              + "; verified = the data evaluated is the published suite, "
              "bit-identical or within the tolerances of docs/benchmark.md):", ""]
    for s in chosen:
        if s.id in records:
            state = suite_state(records[s.id])
            cite = s.id if track == tracks.DEFAULT else tracks.cite(s, track)
            lines.append(f"- `{cite}`: {s.tests}. {state[0].upper()}{state[1:]}.")
    if (summary["source"] == "submitted").any():
        lines += ["", "Rows marked ‡ are submitted results: others' runs, checked by `colonbench results check` and "
                  "kept in the repository's `results/` (docs/benchmark.md, Submitting results)."]
    left = [f"- `{sid}`: {n}." for sid, ns in (notes or {}).items() for n in ns]
    if left:
        lines += ["", "Left out of the tables:", ""] + left
    if skipped:
        lines += ["", f"No results for {', '.join(skipped)}: no method was evaluated there and no shipped results "
                  "match."]
    lines.append("")
    return "\n".join(lines)
