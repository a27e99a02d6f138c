"""The leaderboard: tables rebuilt from stored runs, never edited by hand.

:func:`merge_runs` reads finished run folders (:func:`colonbench.benchmark.evaluate.load_results`)
and refuses to combine runs on different data (dataset manifest, split or
chosen samples), of different tracks (:mod:`colonbench.benchmark.tracks`),
with different noise levels, noise seed or metric settings, or naming the same
method twice. :func:`write_leaderboard` writes

* ``leaderboard.md``: per noise level, a coverage table (MAE, median, bias,
  q95 in percentage points, failed segments scored as the farther of coverage
  0 and 1 and counted; undefined values counted) and a precision / recall
  table (mean, with the median in brackets; failed segments count 0;
  undefined counts), methods ranked by MAE, reference rows (given ground
  truth) last and marked *, the shipped reference results marked † and
  submitted results ‡, as the pages mark them;
* ``leaderboard.csv``: one row per noise level and method with its
  ``source`` (:func:`source`) and every statistic of
  :func:`colonbench.benchmark.summary.summarize`;
* ``leaderboard.json``: the same rows with the runs, data identity and
  versions they came from.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd

from colonbench.benchmark import tracks
from colonbench.benchmark.submitted import is_submitted
from colonbench.benchmark.evaluate import load_results
from colonbench.benchmark.summary import scored_errors, summarize
from colonbench.errors import InputError

#: Settings two runs must share to be compared.
SAME = ("data", "track", "noise_mm", "noise_seed", "thresholds_mm")


def merge_runs(run_dirs, extra=()) -> tuple[dict, pd.DataFrame]:
    """Per-segment results of several runs on the same data, and what they were.

    Parameters
    ----------
    run_dirs : list of path
        Finished run folders.
    extra : iterable of (run record, results DataFrame, label)
        Runs already loaded (the shipped reference results, :mod:`colonbench.benchmark.shipped`).

    Returns
    -------
    meta : dict
        ``data``, ``suite``, ``noise_mm``, ``noise_seed``, ``thresholds_mm`` (shared),
        ``methods`` (name -> record with its ``run``), ``runs`` (paths and versions).
    results : DataFrame
        Every per-segment row.
    """
    items = [(*load_results(r), str(r)) for r in run_dirs] + list(extra)
    if not items:
        raise InputError("no run folders given")
    meta, frames = None, []
    for run, df, label in items:
        meta = add_run(meta, run, label, items[0][2], SAME)
        frames.append(df)
    return meta, pd.concat(frames, ignore_index=True)


def _setting(run: dict, key: str):
    """A run's setting as compared: a suite run's data is its suite, whatever machine made it: its published signature
    where the data verified against it (bit-identical or within tolerance), else the content hash it had."""
    if key == "data" and run.get("suite"):
        return suite_identity(run["suite"])
    if key == "track":
        return tracks.of_run(run)
    return run.get(key)


def suite_identity(record: dict) -> dict:
    """What two runs of a suite must share to be compared: the suite id and, for verified data, the published
    signature it verified against; for unverified data, its own content hash."""
    if record.get("verified"):
        return {"suite": record["id"], "signature": record.get("signature") or record["published_sha256"]}
    return {"suite": record["id"], "sha256": record["sha256"]}


def add_run(meta: dict | None, run: dict, path, first, same) -> dict:
    """``meta`` (started from ``run`` when None) with ``run``'s methods and record added.

    Two runs of one suite compare by the suite's content hash (their HDF5 files may differ byte for byte
    across machines); other runs by their data identity.

    Raises
    ------
    InputError
        ``run`` differs from the first run in one of the settings ``same``, or names a method already there.
    """
    if meta is None:
        meta = {k: tracks.of_run(run) if k == "track" else run[k] for k in same}
        meta.update(suite=run.get("suite"), methods={}, runs=[], _first=run)
    for k in same:
        if k == "track" and tracks.of_run(run) != meta["track"]:
            raise InputError(f"{path} is a run of the {tracks.label(tracks.of_run(run))} and {first} of the "
                             f"{tracks.label(meta['track'])}; a leaderboard never mixes tracks (colonbench "
                             "leaderboard --html puts each track on its own page)")
        if json.dumps(_setting(run, k), sort_keys=True) != json.dumps(_setting(meta["_first"], k), sort_keys=True):
            raise InputError(f"{path} was evaluated with other {k} than {first} "
                             f"({_setting(run, k)!r} vs {_setting(meta['_first'], k)!r}); a leaderboard compares "
                             "runs on the same data only")
    for name, rec in run["methods"].items():
        if name in meta["methods"]:
            raise InputError(f"method {name!r} is in both {meta['methods'][name]['run']} and {path}; "
                             "give each method once")
        meta["methods"][name] = {**rec, "run": str(path)}
    meta["runs"].append({"path": str(path), "versions": run.get("versions", {}), "sessions": run.get("sessions", [])})
    return meta


def source(record: dict) -> str:
    """Where a method's rows came from, by its record's ``run``: ``shipped`` (the shipped reference results),
    ``submitted`` (:mod:`colonbench.benchmark.submitted`), or else the run folder they were read from."""
    run = str(record.get("run", ""))
    return "shipped" if run.startswith("shipped") else "submitted" if is_submitted(record) else run


def table(meta: dict, results: pd.DataFrame) -> pd.DataFrame:
    """Summary rows (:func:`summarize`) with ``version``, ``reference``, ``source`` (:func:`source`), the MAE's 95 %
    bootstrap interval (``coverage_mae_lo``, ``coverage_mae_hi``) and the paired difference of the absolute error
    against the best baseline of the noise level (``baseline``, ``vs_baseline``, ``vs_baseline_lo``,
    ``vs_baseline_hi``, ``vs_baseline_pairs``; points, negative = better), ranked within each noise level."""
    from colonbench.benchmark import stats
    from colonbench.benchmark.registry import BASELINES

    s = summarize(results, meta["thresholds_mm"])
    s["version"] = s["method"].map(lambda m: meta["methods"][m]["version"])
    s["reference"] = s["method"].map(lambda m: bool(meta["methods"][m]["reference"]))
    if meta.get("track", tracks.DEFAULT) != tracks.DEFAULT:   # a method that takes no length answers as on points
        s["takes_length"] = s["method"].map(lambda m: bool(meta["methods"][m].get("takes_length", True)))
    # one seed for every cell: methods scored on the same segments are resampled alike (identical errors give
    # identical intervals), and no cell depends on which others are computed
    ci = {(n, m): stats.mae_interval(scored_errors(g), seed=0)
          for (n, m), g in results.groupby(["noise_mm", "method"])}
    s["coverage_mae_lo"] = [ci[(n, m)]["mae_lo"] for n, m in zip(s["noise_mm"], s["method"])]
    s["coverage_mae_hi"] = [ci[(n, m)]["mae_hi"] for n, m in zip(s["noise_mm"], s["method"])]
    best = stats.best_baseline(s, BASELINES)
    s["baseline"] = s["noise_mm"].map(lambda n: best.get(n, ""))
    for c in ("vs_baseline", "vs_baseline_lo", "vs_baseline_hi", "vs_baseline_pairs"):
        s[c] = math.nan
    for noise, ref in best.items():
        sub = results[results["noise_mm"] == noise]
        d = stats.paired_against(sub, ref).set_index("method")
        for m in d.index:
            at = (s["noise_mm"] == noise) & (s["method"] == m)
            s.loc[at, ["vs_baseline", "vs_baseline_lo", "vs_baseline_hi", "vs_baseline_pairs"]] = \
                d.loc[m, ["diff", "diff_lo", "diff_hi", "pairs"]].to_numpy(float)
    s["source"] = s["method"].map(lambda m: source(meta["methods"][m]))
    s = s.sort_values(["noise_mm", "reference", "coverage_mae", "method"], na_position="last")
    cols = ["noise_mm", "method", "version", "reference"] + (["takes_length"] if "takes_length" in s.columns else [])
    cols += ["source"]
    return s[cols + [c for c in s.columns if c not in cols]].reset_index(drop=True)


def _f(x, digits=2, sign: str = "") -> str:
    return "n/a" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:{sign}.{digits}f}"


def interval(lo, hi, sign: str = "") -> str:
    """``[lo, hi]`` with two decimals, or an empty string when undefined."""
    if lo is None or hi is None or math.isnan(lo) or math.isnan(hi):
        return ""
    return f"[{lo:{sign}.2f}, {hi:{sign}.2f}]"


def data_line(meta: dict, unit: str) -> str:
    """The sentence saying what was evaluated: the suite and its content hash (verified or not), or the data; and
    the track where it is not the points-only one, with how to cite it."""
    d, suite, track = meta["data"], meta.get("suite"), meta.get("track") or tracks.DEFAULT
    on = "" if track == tracks.DEFAULT else (
        f" {tracks.label(track).capitalize()}: each method that takes it is given the segment's nominal arc length" +
        (f"; cite as `{tracks.cite_record(suite, track)}`." if suite else "."))
    if suite:
        return (f"Suite `{suite['id']}` ({d['samples']} {unit}; {suite_state(suite)}; manifest "
                f"`{d['manifest_name']}`, split `{d['split']}`).{on}")
    return (f"Data: manifest `{d['manifest_name']}` (sha256 {str(d['manifest_sha256'])[:12]}), split `{d['split']}`, "
            f"{d['samples']} {unit} (samples sha256 {d['samples_sha256'][:12]}; not a named suite).{on}")


def suite_state(suite: dict) -> str:
    """How a run's suite data stand against the published suite, in words (docs/benchmark.md, Verified suites)."""
    if not suite["verified"]:
        return f"**unverified**: content hash `{suite['sha256'][:16]}`, not the published suite"
    if "signature" not in suite:   # a run recorded before signatures: verified by its content hash
        return f"content hash `{suite['sha256'][:16]}`, verified against the published hash"
    whose = "the data as built" if suite.get("local") else "the published data"
    how = f"bit-identical to {whose}" if suite["bit_identical"] else f"within tolerance of {whose} ({differing(suite)})"
    built = (f"; built here from a download by importer {suite['importer']['name']} {suite['importer']['version']} "
             f"(source digest `{str((suite.get('source') or {}).get('digest'))[:12]}`)" if suite.get("local") else "")
    return f"verified against its signature `{suite['signature']}`, {how}{built}"


def own_data_note(record: dict) -> str | None:
    """Where a method's rows were made on other data than its run's (a shipped method published again on data within
    tolerance of the suite's, decision record 0327: ``methods.<name>.suite`` in run.json), those data in words."""
    own = record.get("suite")
    if not isinstance(own, dict) or own.get("bit_identical"):
        return None
    return f"{own.get('check', 'unchecked')} of the published data ({differing(own)})"


def differing(record: dict) -> str:
    """How many samples of a suite record's data differ from the published data, and how, in words."""
    parts = [f"{record.get('tie_samples', '?')} samples decided otherwise at a near-tie"]
    parts += [f"{record[k]} {what}" for k, what in (("redrawn_samples", "redrawn on the same surface"),
                                                     ("diverged_samples", "diverged")) if record.get(k)]
    return ", ".join(parts)


def marks(record: dict) -> str:
    """The marks after a method's name, from its record: * a reference, † the shipped results, ‡ a submitted result
    (the Markdown tables and the page alike)."""
    return (" *" if record.get("reference") else "") + {"shipped": " †", "submitted": " ‡"}.get(source(record), "")


def _name(r, meta: dict) -> str:
    """A row's method with its marks (:func:`marks`; a row's own ``reference`` flag)."""
    return r["method"] + marks({**meta["methods"].get(r["method"], {}), "reference": r["reference"]})


def markdown(meta: dict, tab: pd.DataFrame, notes=()) -> str:
    """The leaderboard as Markdown (``notes``: submitted results left out, and why)."""
    lines = ["# colonbench leaderboard", "", data_line(meta, "segments") + " Input noise: Gaussian, sigma in mm, "
             f"seed {meta['noise_seed']}. Coverage errors in percentage points (estimated - true); MAE with its 95 % "
             "bootstrap interval over segments; Δ = the paired mean difference of the absolute error against the "
             "best baseline of the noise level, with its interval (negative: better). Precision and recall at "
             f"{' and '.join(f'{t:g}' for t in meta['thresholds_mm'])} mm. A failed segment (no valid answer; "
             "counted in *failed*) is scored as the farther of coverage 0 and 1 in every coverage statistic and the "
             "ranking, as precision and recall 0 and as a truth outside its interval: failing never improves a "
             "score. *Undefined*: answered segments where a metric has no value.", "",
             "Rows marked * are references that bound the problem, not methods: they are given ground truth (the GT "
             "target heatmap or centerline) or guess the training data's mean coverage.", ""]
    if any(source(rec) == "shipped" for rec in meta["methods"].values()):
        lines += ["Rows marked † are the shipped reference results: colonbench's own runs of its built-in methods on "
                  "the published suite, merged in (`source` `shipped` in leaderboard.csv).", ""]
        elsewhere = [f"The shipped rows of {n} were made on data {own_data_note(rec)}."
                     for n, rec in meta["methods"].items() if source(rec) == "shipped" and own_data_note(rec)]
        lines += elsewhere + ([""] if elsewhere else [])
    if any(is_submitted(rec) for rec in meta["methods"].values()):
        lines += ["Rows marked ‡ are submitted results: others' runs of the suite, checked by `colonbench results "
                  "check` and kept in the repository's `results/` (docs/benchmark.md, Submitting results).", ""]
    lines += [f"Left out of this table: {n}." for n in notes] + ([""] if notes else [])
    ths = meta["thresholds_mm"]
    on_length = "takes_length" in tab.columns
    if on_length:
        lines += ["*length*: whether the method took the segment's length; one that takes none (its `estimate` has no "
                  "`length_mm`) answers as on the points-only track.", ""]
    for noise, g in tab.groupby("noise_mm", sort=True):
        lines += [f"## Noise sigma = {noise:g} mm", "",
                  "| method | version | " + ("length | " if on_length else "") + "segments | MAE [95 % CI] "
                  "| Δ vs best baseline [95 % CI] | median | bias | q95 | undefined | failed | s/segment |",
                  "|---|---|" + ("---|" if on_length else "") + "---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
        for _, r in g.iterrows():
            name = _name(r, meta)
            vs = ("(best baseline)" if r["method"] == r["baseline"] else
                  f"{_f(r['vs_baseline'], 2, '+')} {interval(r['vs_baseline_lo'], r['vs_baseline_hi'], '+')}"
                  if r["baseline"] and not math.isnan(r["vs_baseline"]) else "n/a")
            given = ("given | " if r["takes_length"] else "takes none | ") if on_length else ""
            lines.append(f"| {name} | {r['version']} | {given}{r['segments']} | {_f(r['coverage_mae'])} "
                         f"{interval(r['coverage_mae_lo'], r['coverage_mae_hi'])} | {vs} | "
                         f"{_f(r['coverage_median'])} | {_f(r['coverage_bias'])} | {_f(r['coverage_q95'])} | "
                         f"{r['coverage_undefined']} | {r['failed']} | {_f(r['seconds'], 3)} |")
        base = g["baseline"].iloc[0] if len(g) else ""
        if base:
            lines += ["", f"Best baseline at this noise level: `{base}`."]
        lines += interval_lines(g)
        head = ["method"] + [f"{w} {pr} @{t:g}" for t in ths for w in ("holes", "centerline") for pr in ("P", "R")]
        lines += ["", "Precision (P) and recall (R), mean (median); undefined segments in the last column.", "",
                  "| " + " | ".join(head) + " | undefined (holes / centerline) |",
                  "|---|" + "---:|" * (len(head) - 1) + "---:|"]
        for _, r in g.iterrows():
            cells = []
            for t in ths:
                for w in ("holes", "centerline"):
                    for pr in ("precision", "recall"):
                        c = f"{w}_{pr}_{t:g}mm"
                        cells.append(f"{_f(r[c + '_mean'])} ({_f(r[c + '_median'])})")
            t2 = f"{ths[-1]:g}mm"
            undef = (f"{max(r[f'holes_precision_{t2}_undefined'], r[f'holes_recall_{t2}_undefined'])} / "
                     f"{max(r[f'centerline_precision_{t2}_undefined'], r[f'centerline_recall_{t2}_undefined'])}")
            lines.append(f"| {_name(r, meta)} | " + " | ".join(cells) + f" | {undef} |")
        lines.append("")
    lines += ["Breakdowns by hole model, segment length, true coverage, unseen end and noise: breakdowns.md. Runs: "
              + ", ".join(f"`{r['path']}`" for r in meta["runs"]) + ".", ""]
    return "\n".join(lines)


def interval_lines(g: pd.DataFrame) -> list[str]:
    """The coverage-interval table of one noise level: methods that give intervals, the share of truths inside and
    the mean width; empty when no method gives any."""
    if "interval_segments" not in g.columns or not (g["interval_segments"] > 0).any():
        return []
    lines = ["", "Coverage intervals (methods without: n/a): the share of segments whose true coverage lies inside "
             "the method's interval (completion's are 90 % intervals), and their mean width; the share it flags for "
             "`review`, the share of the segments off by more than 15 points it flags, and the share of its flags "
             "that are.", "",
             "| method | segments with an interval | truth inside | mean width, points | flagged | off > 15 flagged "
             "| flags right |", "|---|---:|---:|---:|---:|---:|---:|"]
    for _, r in g.iterrows():
        review = " | ".join(f"{_f(r.get(k, np.nan), 0)} %" if np.isfinite(r.get(k, np.nan)) else "n/a"
                            for k in ("review_flagged", "review_recall", "review_precision"))
        if r["interval_segments"] > 0:
            lines.append(f"| {r['method']} | {r['interval_segments']} | {_f(r['interval_covered'], 1)} % | "
                         f"{_f(r['interval_width'], 1)} | {review} |")
        else:
            lines.append(f"| {r['method']} | 0 | n/a | n/a | {review} |")
    return lines


def breakdowns(results: pd.DataFrame) -> pd.DataFrame:
    """MAE with its interval and bias per method, noise level and group, for every grouping of
    :data:`colonbench.benchmark.stats.BREAKDOWNS` that has more than one group."""
    from colonbench.benchmark import stats

    frames = [stats.breakdown(results, by) for by in stats.BREAKDOWNS]
    frames = [f for f in frames if f["group"].nunique() > 1 or f["by"].eq("noise_mm").all() and len(f)]
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame(columns=stats.BREAKDOWN_COLUMNS)


def breakdown_markdown(meta: dict, bd: pd.DataFrame) -> str:
    """The breakdowns as Markdown: per grouping and noise level, methods x groups, MAE [95 % CI] (n)."""
    lines = ["# colonbench leaderboard: breakdowns", "", data_line(meta, "segments") + " Coverage MAE in points "
             "with its 95 % bootstrap interval over the group's segments, and the group's size.", ""]
    titles = {"hole_model": "hole model", "length_mm": "segment length, mm", "true_coverage": "true coverage",
              "unseen_end": "an end never seen", "noise_mm": "noise sigma, mm"}
    for by, g in bd.groupby("by", sort=False):
        noises = [None] if by == "noise_mm" else sorted(g["noise_mm"].unique())
        for noise in noises:
            h = g if noise is None else g[g["noise_mm"] == noise]
            groups = sorted(h["group"].unique(), key=lambda x: (len(x), x)) if by != "true_coverage" else \
                sorted(h["group"].unique())
            lines += [f"## By {titles.get(by, by)}" + ("" if noise is None else f", noise {noise:g} mm"), "",
                      "| method | " + " | ".join(groups) + " |", "|---|" + "---:|" * len(groups)]
            for m, r in h.groupby("method", sort=True):
                cells = {x["group"]: f"{_f(x['mae'])} {interval(x['mae_lo'], x['mae_hi'])} ({x['segments']})"
                         for _, x in r.iterrows()}
                lines.append(f"| {m} | " + " | ".join(cells.get(c, "") for c in groups) + " |")
            for m, r in h[h["interval_covered"].notna()].groupby("method", sort=True):
                cells = {x["group"]: f"{_f(x['interval_covered'], 0)} % inside, {_f(x['interval_width'], 1)} wide"
                         for _, x in r.iterrows()}
                lines.append(f"| {m}: interval | " + " | ".join(cells.get(c, "") for c in groups) + " |")
            lines.append("")
    return "\n".join(lines)


def write_leaderboard(run_dirs, out, figures: bool = True, extra=(), notes=()) -> dict:
    """Write ``leaderboard.md``, ``.csv`` and ``.json`` (and the figures) for runs on the same data.

    Whole-colon runs (``evaluate --task colon``) get their own leaderboard
    (:func:`colonbench.reports.colon_leaderboard.write_colon_leaderboard`). ``extra``: runs already loaded,
    as :func:`merge_runs` takes them (whole-colon ones as ``(run, segments, colons, label)``); ``notes``: what
    the tables say was left out of them (:func:`colonbench.benchmark.submitted.leaderboard_items`).

    Returns
    -------
    dict
        ``{"markdown": text, "paths": [written files]}``.
    """
    from colonbench.benchmark.colon_evaluate import is_colon_run

    colon = [is_colon_run(r) for r in run_dirs] + [item[0].get("task") == "colon" for item in extra]
    if any(colon):
        if not all(colon):
            raise InputError("some runs are whole-colon runs (evaluate --task colon) and some segment runs; a "
                             "leaderboard compares runs of one task")
        from colonbench.reports.colon_leaderboard import write_colon_leaderboard

        return write_colon_leaderboard(run_dirs, out, figures=figures, extra=extra)
    meta, results = merge_runs(run_dirs, extra)
    tab = table(meta, results)
    bd = breakdowns(results)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    text = markdown(meta, tab, notes)
    paths = [out / "leaderboard.md", out / "leaderboard.csv", out / "leaderboard.json", out / "breakdowns.md",
             out / "breakdowns.csv"]
    paths[0].write_text(text)
    tab.to_csv(paths[1], index=False)
    paths[3].write_text(breakdown_markdown(meta, bd))
    bd.to_csv(paths[4], index=False)
    paths[2].write_text(json.dumps({"data": meta["data"], "suite": meta["suite"], "track": meta["track"],
                                    "noise_mm": meta["noise_mm"],
                                    "noise_seed": meta["noise_seed"], "thresholds_mm": meta["thresholds_mm"],
                                    "methods": meta["methods"], "runs": meta["runs"], "notes": list(notes),
                                    "rows": json.loads(tab.to_json(orient="records"))}, indent=1))
    if figures:
        from colonbench.reports import figures as fig

        paths += fig.all_figures(results, tab, [Path(r) for r in run_dirs], out)
    return {"markdown": text, "paths": paths}

