"""The leaderboard: tables rebuilt from stored runs, never edited by hand.

:func:`merge_runs` reads finished run folders (:func:`colonbench.benchmark.evaluate.load_results`)
and refuses to combine runs on different data (dataset manifest, split or
chosen samples), with different noise levels, noise seed or metric settings,
or naming the same method twice. :func:`write_leaderboard` writes

* ``leaderboard.md``: per noise level, a coverage table (MAE, median, bias,
  q95 in percentage points; undefined and failed segments counted) and a
  precision / recall table (mean, with the median in brackets; undefined
  counts), methods ranked by MAE, reference rows (given ground truth) last
  and marked;
* ``leaderboard.csv``: one row per noise level and method with every
  statistic of :func:`colonbench.benchmark.summary.summarize`;
* ``leaderboard.json``: the same rows with the runs, data identity and
  versions they came from.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import pandas as pd

from colonbench.benchmark.evaluate import load_results
from colonbench.benchmark.summary import summarize
from colonbench.errors import InputError

#: Settings two runs must share to be compared.
SAME = ("data", "noise_mm", "noise_seed", "thresholds_mm")


def merge_runs(run_dirs) -> tuple[dict, pd.DataFrame]:
    """Per-segment results of several runs on the same data, and what they were.

    Returns
    -------
    meta : dict
        ``data``, ``noise_mm``, ``noise_seed``, ``thresholds_mm`` (shared),
        ``methods`` (name -> record with its ``run``), ``runs`` (paths and versions).
    results : DataFrame
        Every per-segment row.
    """
    run_dirs = [Path(r) for r in run_dirs]
    if not run_dirs:
        raise InputError("no run folders given")
    meta, frames = None, []
    for r in run_dirs:
        run, df = load_results(r)
        meta = add_run(meta, run, r, run_dirs[0], SAME)
        frames.append(df)
    return meta, pd.concat(frames, ignore_index=True)


def add_run(meta: dict | None, run: dict, path, first, same) -> dict:
    """``meta`` (started from ``run`` when None) with ``run``'s methods and record added.

    Raises
    ------
    InputError
        ``run`` differs from the first run in one of the settings ``same``, or names a method already there.
    """
    if meta is None:
        meta = {k: run[k] for k in same}
        meta.update(methods={}, runs=[])
    for k in same:
        if json.dumps(run[k], sort_keys=True) != json.dumps(meta[k], sort_keys=True):
            raise InputError(f"{path} was evaluated with other {k} than {first} "
                             f"({run[k]!r} vs {meta[k]!r}); a leaderboard compares runs on the same data only")
    for name, rec in run["methods"].items():
        if name in meta["methods"]:
            raise InputError(f"method {name!r} is in both {meta['methods'][name]['run']} and {path}; "
                             "give each method once")
        meta["methods"][name] = {**rec, "run": str(path)}
    meta["runs"].append({"path": str(path), "versions": run.get("versions", {}), "sessions": run.get("sessions", [])})
    return meta


def table(meta: dict, results: pd.DataFrame) -> pd.DataFrame:
    """Summary rows (:func:`summarize`) with ``version`` and ``reference``, ranked within each noise level."""
    s = summarize(results, meta["thresholds_mm"])
    s["version"] = s["method"].map(lambda m: meta["methods"][m]["version"])
    s["reference"] = s["method"].map(lambda m: bool(meta["methods"][m]["reference"]))
    s = s.sort_values(["noise_mm", "reference", "coverage_mae", "method"], na_position="last")
    cols = ["noise_mm", "method", "version", "reference"]
    return s[cols + [c for c in s.columns if c not in cols]].reset_index(drop=True)


def _f(x, digits=2) -> str:
    return "n/a" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.{digits}f}"


def markdown(meta: dict, tab: pd.DataFrame) -> str:
    """The leaderboard as Markdown."""
    d = meta["data"]
    lines = ["# colonbench leaderboard", "",
             f"Data: manifest `{d['manifest_name']}` (sha256 {str(d['manifest_sha256'])[:12]}), split `{d['split']}`, "
             f"{d['samples']} segments (samples sha256 {d['samples_sha256'][:12]}). Input noise: Gaussian, sigma in "
             f"mm, seed {meta['noise_seed']}. Coverage errors in percentage points (estimated - true); precision and "
             f"recall at {' and '.join(f'{t:g}' for t in meta['thresholds_mm'])} mm (colonbench's docs/benchmark.md).", "",
             "Rows marked * are references that bound the problem, not methods: they are given ground truth (the GT "
             "target heatmap or centerline) or guess the training data's mean coverage.", ""]
    ths = meta["thresholds_mm"]
    for noise, g in tab.groupby("noise_mm", sort=True):
        lines += [f"## Noise sigma = {noise:g} mm", "",
                  "| method | version | segments | MAE | median | bias | q95 | undefined | failed | s/segment |",
                  "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
        for _, r in g.iterrows():
            name = r["method"] + (" *" if r["reference"] else "")
            lines.append(f"| {name} | {r['version']} | {r['segments']} | {_f(r['coverage_mae'])} | "
                         f"{_f(r['coverage_median'])} | {_f(r['coverage_bias'])} | {_f(r['coverage_q95'])} | "
                         f"{r['coverage_undefined']} | {r['failed']} | {_f(r['seconds'], 3)} |")
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
            lines.append(f"| {r['method'] + (' *' if r['reference'] else '')} | " + " | ".join(cells) + f" | {undef} |")
        lines.append("")
    lines += ["Runs: " + ", ".join(f"`{r['path']}`" for r in meta["runs"]) + ". Rebuild with "
              "`colonbench leaderboard RUN... --out DIR`.", ""]
    return "\n".join(lines)


def write_leaderboard(run_dirs, out, figures: bool = True) -> dict:
    """Write ``leaderboard.md``, ``.csv`` and ``.json`` (and the figures) for runs on the same data.

    Whole-colon runs (``evaluate --task colon``) get their own leaderboard
    (:func:`colonbench.reports.colon_leaderboard.write_colon_leaderboard`).

    Returns
    -------
    dict
        ``{"markdown": text, "paths": [written files]}``.
    """
    from colonbench.benchmark.colon_evaluate import is_colon_run

    colon = [is_colon_run(r) for r in run_dirs]
    if any(colon):
        if not all(colon):
            raise InputError("some runs are whole-colon runs (evaluate --task colon) and some segment runs; a "
                             "leaderboard compares runs of one task")
        from colonbench.reports.colon_leaderboard import write_colon_leaderboard

        return write_colon_leaderboard(run_dirs, out, figures=figures)
    meta, results = merge_runs(run_dirs)
    tab = table(meta, results)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    text = markdown(meta, tab)
    paths = [out / "leaderboard.md", out / "leaderboard.csv", out / "leaderboard.json"]
    paths[0].write_text(text)
    tab.to_csv(paths[1], index=False)
    paths[2].write_text(json.dumps({"data": meta["data"], "noise_mm": meta["noise_mm"],
                                    "noise_seed": meta["noise_seed"], "thresholds_mm": meta["thresholds_mm"],
                                    "methods": meta["methods"], "runs": meta["runs"],
                                    "rows": json.loads(tab.to_json(orient="records"))}, indent=1))
    if figures:
        from colonbench.reports import figures as fig

        paths += fig.all_figures(results, tab, [Path(r) for r in run_dirs], out)
    return {"markdown": text, "paths": paths}

