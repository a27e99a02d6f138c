"""The leaderboard as a static web site: ``colonbench leaderboard RUN... --out SITE --html``.

:func:`write_site` takes run folders (``colonbench evaluate``, ``score``) and
``colonbench benchmark --out`` folders, groups their runs by suite (or data)
and *track* (``track`` in run.json, ``points`` where absent), merges the
shipped results of the built-in methods and the submitted results of the
repository's ``results/`` (marked ‡; :mod:`colonbench.benchmark.submitted`) as
``colonbench benchmark`` does, and writes, with no server needed (``file://``
or a project page):

* ``SITE/index.html``: per page a chart of every method's coverage MAE with its
  95 % interval per noise level, failures marked (:mod:`colonbench.reports.chart`,
  inline SVG), then the pages, what each suite tests and how to cite it, and the
  same MAE of every method on every page in tables, per noise level;
* ``SITE/<suite>/<track>/index.html``: the page's chart and the figures that
  :func:`colonbench.reports.leaderboard.write_leaderboard` writes into that
  folder, then the tables (:mod:`colonbench.reports.site_tables`), sized for a
  1280 px window: per noise level the leaderboard table (MAE with its interval,
  failures, ...), the interval and review scores, precision and recall;
  breakdowns; every statistic;
* ``SITE/methods/<method>.html``: a method's version, how it was run, its model
  card where one ships, and the package versions and machine its run recorded.

The pages are rendered from autoescaping Jinja2 templates (``templates/``:
``suite.html``, ``index.html``, each extending ``page.html``;
:func:`colonbench.reports.webpage.render`); the chart and the tables come to them
as HTML built with every string from a run (method names, versions, command
lines) escaped. Every table sorts by a click on a column header
(:mod:`colonbench.reports.webpage`: a small inline script). The evaluation
server's live page of a hidden suite is the same suite page
(:mod:`colonbench.reports.live`).
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pandas as pd

from colonbench._version import __version__
from colonbench.benchmark import tracks
from colonbench.benchmark.runfolder import RUN_FILE, read_run, write_json
from colonbench.errors import InputError
from colonbench.reports.chart import mae_chart
from colonbench.reports.leaderboard import data_line, own_data_note, suite_state
from colonbench.reports.site_tables import (
    breakdown_tables, chart_rows, every_tables, interval_table, main_table, method_cell, pr_table, row_attrs, source)
from colonbench.reports.webpage import (
    esc, fmt, inline, interval_cell, kv_table, page, render, safe, slug, table, with_interval)

#: The track of a run whose run.json names none.
DEFAULT_TRACK = tracks.DEFAULT
#: Marks a site folder (which a rebuild may replace) and lists its pages.
SITE_FILE = "site.json"
#: Model cards that ship, by the model named at the head of a method's version (``small@avg9,...``).
CARDS = {"small": "models/MODEL_CARD.md"}
#: What each figure of a page shows (a triplet figure is named by its file).
CAPTIONS = {"boxplots": "Box plots per noise level (the paper's Fig. 4): hole and centerline precision and recall "
                        "at 2 mm and the absolute coverage error, by method.",
            "scatter": "Estimated against true coverage, one panel per method.",
            "colon-maps": "One colon's map, truth and error side by side."}
#: What the headline chart shows, under it.
CHART_CAPTION = ("Coverage MAE in percentage points: a dot at the MAE, a bar over its 95 % bootstrap interval over "
                 "segments; orange: the runs given, grey: references (*); † shipped, ‡ submitted results. ✕ n failed: "
                 "the method failed on n samples, each scored as the farther of coverage 0 and 1 (so counted in the "
                 "MAE). A name links to the method's page.")

# ---------------------------------------------------------------------------------------------------- the runs


def expand(paths) -> tuple[list[Path], list[tuple[str, str]]]:
    """Run folders and ``(suite id, track)`` pairs in ``paths``: a run folder is itself; a ``benchmark --out``
    folder gives its ``runs/<suite>/`` and the suites of its ``leaderboard.json`` on its track (shipped results only
    where it ran none).

    Raises
    ------
    InputError
        A path that is neither.
    """
    runs, ids = [], []
    for p in map(Path, paths):
        if (p / RUN_FILE).is_file():
            runs.append(p)
            continue
        lb = p / "leaderboard.json"
        found = sorted(d for d in (p / "runs").glob("*") if (d / RUN_FILE).is_file()) if p.is_dir() else []
        try:
            record = json.loads(lb.read_text()) if lb.is_file() else {}
            named = [(sid, str(record.get("track") or DEFAULT_TRACK)) for sid in record.get("suites", {})]
        except (json.JSONDecodeError, AttributeError) as exc:
            raise InputError(f"{lb}: unreadable ({exc})") from None
        if not found and not named:
            what = "no such folder" if not p.exists() else "neither a run folder (no run.json) nor a colonbench " \
                "benchmark --out folder (no runs/<suite>/run.json, no leaderboard.json naming suites)"
            raise InputError(f"{p}: {what}")
        runs, ids = runs + found, ids + named
    return list({r.resolve(): r for r in reversed(runs)}.values())[::-1], list(dict.fromkeys(ids))


def _suite(sid):
    from colonbench.benchmark import suites

    try:
        return suites.get(sid)
    except InputError:   # a suite this version of colonbench does not know: no shipped results, no description
        return None


def groups(paths, shipped: bool = True, submitted: bool = True) -> dict:
    """``{(page id, track): {"runs", "records", "extra", "notes", "suite"}}``: the runs of each suite (or data) and
    track, and the shipped and submitted results of that suite and track merged into them as ``colonbench
    benchmark`` merges them (its runs' data verified, the methods they hold left out of the others; ``notes``: the
    submitted results left out)."""
    from colonbench.benchmark.submitted import leaderboard_items

    run_dirs, ids = expand(paths)
    out = {}
    for d in run_dirs:
        run = read_run(d)
        rec, data = run.get("suite") or {}, run.get("data") or {}
        pid = rec.get("id") or "-".join(str(x) for x in (data.get("manifest_name", "data"), data.get("split", ""),
                                                          str(data.get("samples_sha256", ""))[:8]))
        g = out.setdefault((pid, str(run.get("track") or DEFAULT_TRACK)),
                           {"runs": [], "records": [], "extra": [], "notes": [],
                            "suite": _suite(pid) if rec else None})
        g["runs"].append(d)
        g["records"].append((run, str(d)))
    for sid, track in ids if shipped or submitted else ():
        s = _suite(sid)
        if s is not None:
            out.setdefault((s.id, track), {"runs": [], "records": [], "extra": [], "notes": [], "suite": s})
    for (pid, track), g in out.items():
        verified = all((run.get("suite") or {}).get("verified") for run, _ in g["records"])
        if (shipped or submitted) and g["suite"] is not None and track in tracks.TRACKS and verified:
            g["extra"], g["notes"] = leaderboard_items(
                g["suite"], track, mine={m for run, _ in g["records"] for m in run["methods"]}, shipped=shipped,
                submitted=submitted)
            g["records"] += [(item[0], item[-1]) for item in g["extra"]]
    return {k: g for k, g in out.items() if g["runs"] or g["extra"]}


# ---------------------------------------------------------------------------------------------------- the pages


def headline(tab: pd.DataFrame, suite) -> pd.DataFrame:
    """Rows ``noise_mm``, ``method``, ``mae``, ``mae_lo``, ``mae_hi``, ``failed`` of a leaderboard table (a
    whole-colon table: the segment MAE of its headline track, as the cross-suite table of ``colonbench benchmark``,
    and its failed segments and maps)."""
    col = "coverage_mae" if "coverage_mae" in tab.columns else "segment_mae"
    if col == "segment_mae":
        tab = tab[tab["track"] == (getattr(suite, "headline_track", None) or tab["track"].iloc[0])]
    failed = sum(tab[c].fillna(0) for c in ("failed", "failed_segments", "failed_maps") if c in tab.columns)
    return tab.assign(failed=failed if len(tab) else 0).rename(
        columns={col: "mae", f"{col}_lo": "mae_lo", f"{col}_hi": "mae_hi"})[
        ["noise_mm", "method", "mae", "mae_lo", "mae_hi", "failed"]]


def section(title: str, tables: str, id: str | None = None, note: str | None = None,
            details: str | None = None) -> dict:
    """A section of a suite page (``parts.html``'s ``section``): its heading, an optional note, its tables (HTML of
    :mod:`colonbench.reports.site_tables`, every string from a run escaped there), folded under ``details`` if
    given."""
    return {"title": title, "tables": safe(tables), "id": id, "note": note, "details": details}


def chart_svg(mae: pd.DataFrame, methods: dict, root: str, title: str, cid: str):
    """The headline chart of one page (:func:`colonbench.reports.chart.mae_chart`, every name escaped there)."""
    return safe(mae_chart(chart_rows(mae, methods, root), title, cid))


def suite_page(key, g: dict, folder: Path, lb: dict, tab: pd.DataFrame, bd, figures: list[str],
               mae: pd.DataFrame) -> str:
    """The page of one suite (or data) and track (``suite.html``): what it is, its figures (the headline chart
    first), then its tables."""
    (pid, track), s, root, methods = key, g["suite"], "../../", lb["methods"]
    unit = "reconstructions" if lb.get("task") == "colon" else "segments"
    sections = []
    for noise, h in tab.groupby("noise_mm", sort=True):
        n = f"noise{noise:g}"
        sections.append(section(f"Noise sigma = {noise:g} mm", main_table(f"coverage-{n}", h, methods, root)
                                + interval_table(f"intervals-{n}", h, methods, root)
                                + pr_table(f"pr-{n}", h, methods, root), id=n))
    extra = pd.DataFrame(lb.get("in_context") or [])
    if len(extra):
        sections.append(section("In context vs segment-only, the same segments", table(
            "in-context", [(c, extra[c].dtype.kind in "if") for c in extra.columns],
            [({}, [(esc(t), v) for t, v in (fmt(x, c) for c, x in r.items())]) for _, r in extra.iterrows()])))
    if bd is not None and len(bd):
        sections.append(section("Breakdowns", breakdown_tables(bd, methods, root),
                                note="Coverage MAE in percentage points with its 95 % interval over the group's "
                                     "segments, and the group's size."))
    sections.append(section("Every statistic", every_tables(tab, methods, root),
                             details="the leaderboard table as computed (leaderboard.csv; the versions are on the "
                                     "methods' pages)"))
    return render(
        "suite.html", title=f"{pid} · track {track}: colonbench leaderboard", root=root,
        heading=f"{pid} · track {track}", tests=s.tests if s is not None else None,
        cite=tracks.cite(s, track) if s is not None else None,
        data=safe(inline(data_line({"data": lb["data"], "suite": lb.get("suite"), "track": track}, unit))),
        noise_levels=", ".join(f"{n:g}" for n in lb["noise_mm"]), noise_seed=lb["noise_seed"],
        notes=list(lb.get("notes") or ()),
        files=[f for f in ("leaderboard.md", "leaderboard.csv", "leaderboard.json", "breakdowns.md", "breakdowns.csv")
               if (folder / f).is_file()],
        chart=chart_svg(mae, methods, root, f"{pid} · track {track}", "chart"), chart_caption=CHART_CAPTION,
        figures=[{"src": f, "caption": CAPTIONS.get(f[:-4], f[:-4].replace("-", " "))} for f in figures],
        sections=sections, runs=[r["path"] for r in lb["runs"]])


def model_card(version: str) -> str | None:
    """The text of the model card that ships for the model a method's version names, if any."""
    from importlib import resources

    name = CARDS.get(str(version).split("@", 1)[0]) if "@" in str(version) else None
    card = resources.files("colonbench.completion").joinpath(name) if name else None
    return card.read_text() if card is not None and card.is_file() else None


def method_page(name: str, seen: list[dict]) -> str:
    """A method's page: per page it appears on, its version, how it was run, its MAE, model card, environment."""
    body = [f"<h1>{esc(name)}</h1>"]
    for a in seen:
        rec, run = a["record"], a["run"]
        how = {"version": rec.get("version", ""), "spec": rec.get("spec", ""), "class": rec.get("class", ""),
               "reference": "yes" if rec.get("reference") else "no",
               "given ground truth": "yes" if rec.get("uses_truth") else "no",
               **({"takes the length": "yes" if rec["takes_length"] else "no (answers as on the points track)"}
                  if "takes_length" in rec else {}),
               "source": {"shipped": "shipped reference results",
                          "submitted": f"submitted results ({rec.get('run', '')[len('submitted '):]} in the "
                                       "repository's results/)"}.get(source(rec), rec.get("run", "")),
               **({"data": own_data_note(rec)} if own_data_note(rec) else {})}
        mae = [({}, [(esc(f"{r['noise_mm']:g}"), repr(r["noise_mm"])),
                     (esc(with_interval(r, "mae")[0]), fmt(r["mae"])[1])]) for _, r in a["mae"].iterrows()]
        body += [f'<h2><a href="../{esc(a["pid"])}/{esc(a["track"])}/index.html">{esc(a["pid"])} · track '
                 f'{esc(a["track"])}</a></h2>', kv_table(how),
                 table(f"mae-{a['pid']}-{a['track']}", [("noise, mm", True), ("MAE [95 % CI]", True)], mae)]
        card = model_card(rec.get("version", ""))
        body.append("<h3>Model card</h3>" + (
            f"<details><summary>the shipped model card</summary><pre>{esc(card)}</pre></details>" if card else
            "<p>None ships: the run records the method's spec, class and version.</p>"))
        env, versions = rec.get("environment") or run.get("environment"), rec.get("versions") or run.get("versions")
        env = {k: ", ".join(map(str, v)) if isinstance(v, list) else v for k, v in (env or {}).items()}
        body.append("<h3>Environment (run.json)</h3>" + (kv_table(env) if env else "<p>Not recorded by this run.</p>"))
        if versions:
            body.append("<h3>Package versions</h3>" + kv_table(versions))
        if run.get("sessions"):
            cols = list(run["sessions"][0])
            body.append("<h3>Sessions</h3>" + table(None, [(c, False) for c in cols], [
                ({}, [(esc(s.get(c, "")), None) for c in cols]) for s in run["sessions"]]))
    return page(f"{name}: colonbench leaderboard", "\n".join(body), "../")


def index_page(pages: list[dict]) -> str:
    """The site's front page (``index.html``): the headline chart of each page, the pages, and every method's MAE
    on each, per noise level."""
    rows = []
    for p in pages:
        s, lb = p["suite"], p["lb"]
        mine = sorted(m for m, r in lb["methods"].items() if source(r) == "mine")
        rows.append(({"data-page": p["name"]}, [
            (f'<a href="{esc(p["name"])}/index.html">{esc(p["pid"])}</a>', p["pid"]), (esc(p["track"]), p["track"]),
            (esc(s.tests if s else "not a named suite"), None),
            (esc(tracks.cite(s, p["track"])) if s else "", None),
            (inline(suite_state(lb["suite"])) if lb.get("suite") else "", None),
            (esc(", ".join(mine) or "none (shipped or submitted results only)"), None)]))
    charts = [{"href": f"{p['name']}/index.html", "name": f"{p['pid']} · track {p['track']}",
               "svg": chart_svg(p["mae"], p["lb"]["methods"], "", f"{p['pid']} · track {p['track']}", f"chart-{i}")}
              for i, p in enumerate(pages, 1)]
    recs = {m: r for p in pages for m, r in p["lb"]["methods"].items()}
    summary = pd.concat([p["mae"].assign(page=p["name"]) for p in pages], ignore_index=True)
    summaries = []
    for noise, g in summary.groupby("noise_mm", sort=True):
        keyed = {(r["method"], r["page"]): r for _, r in g.iterrows()}
        trs = [(row_attrs(m, recs), [method_cell(m, recs, "")] + [
            ("—", "") if (m, p["name"]) not in keyed else interval_cell(keyed[m, p["name"]], "mae") for p in pages])
            for m in dict.fromkeys(chart_rows(g, recs, "")["method"])]
        heads = [("method", False)] + [(f"{p['pid']} · track {p['track']}", True) for p in pages]
        summaries.append({"noise": f"{noise:g}", "table": safe(table(f"summary-noise{noise:g}", heads, trs))})
    return render("index.html", title="colonbench leaderboard", root="", charts=charts, chart_caption=CHART_CAPTION,
                  pages=safe(table("pages", [("suite", False), ("track", False), ("what it tests", False),
                                             ("cite as", False), ("data", False), ("runs given", False)], rows)),
                  summaries=summaries)


# ---------------------------------------------------------------------------------------------------- the site


def _write_pages(found: dict, out: Path, figures: bool) -> tuple[list, dict, list]:
    """Each group's page, the methods' pages and the index under ``out``: (pages, methods seen, files written)."""
    from colonbench.reports.leaderboard import write_leaderboard

    pages, written, seen = [], [], {}
    for key in sorted(found):
        g, (pid, track) = found[key], (slug(key[0]), slug(key[1]))
        folder = out / pid / track
        res = write_leaderboard(g["runs"], folder, figures=figures, extra=g["extra"], notes=g["notes"])
        lb = json.loads((folder / "leaderboard.json").read_text())
        tab = pd.read_csv(folder / "leaderboard.csv")
        bd = pd.read_csv(folder / "breakdowns.csv") if (folder / "breakdowns.csv").is_file() else None
        pngs = [Path(p).name for p in res["paths"] if str(p).endswith(".png")]
        mae = headline(tab, g["suite"])
        (folder / "index.html").write_text(suite_page(key, g, folder, lb, tab, bd, pngs, mae))
        pages.append({"pid": pid, "track": track, "name": f"{pid}/{track}", "suite": g["suite"], "lb": lb,
                      "mae": mae})
        written += [*res["paths"], folder / "index.html"]
        runs = {label: run for run, label in g["records"]}
        for name, rec in lb["methods"].items():
            seen.setdefault(name, []).append({"pid": pid, "track": track, "record": rec,
                                              "run": runs.get(rec.get("run"), {}), "mae": mae[mae["method"] == name]})
    (out / "methods").mkdir()
    for name, where in sorted(seen.items()):
        written.append(out / "methods" / f"{slug(name)}.html")
        written[-1].write_text(method_page(name, where))
    (out / "index.html").write_text(index_page(pages))
    return pages, seen, written


def write_site(paths, out, figures: bool = True, shipped: bool = True, submitted: bool = True) -> dict:
    """Write the leaderboard site of run folders and ``benchmark --out`` folders into ``out``.

    Parameters
    ----------
    paths : list of path
        Run folders and ``colonbench benchmark --out`` folders.
    out : path
        The site folder: new, empty, or a site written before (replaced once the new one is complete).
    figures : bool
        Draw each page's figures.
    shipped : bool
        Merge the shipped results of the built-in methods where the runs' data verified.
    submitted : bool
        Merge the submitted results (the repository's ``results/``) likewise, less those named as a method of the
        runs: the page says which were left out.

    Returns
    -------
    dict
        ``index`` (the front page's path), ``pages`` (``suite/track`` of each page), ``methods`` (method names),
        ``paths`` (every file written).

    Raises
    ------
    InputError
        A path that is neither kind of folder, runs that cannot be compared, or an unsuitable ``out``.
    """
    final = Path(out)
    if final.exists() and not final.is_dir():
        raise InputError(f"{final} is a file: give a folder for the site")
    if final.is_dir() and not (final / SITE_FILE).is_file() and any(not p.name.startswith(".")
                                                                    for p in final.iterdir()):
        raise InputError(f"{final} is not empty and holds no {SITE_FILE}: give a new or empty folder for the site")
    found = groups(paths, shipped=shipped, submitted=submitted)
    if not found:
        raise InputError(f"nothing to show for {', '.join(map(str, paths))}: no runs, and no shipped results merged")
    out = final.with_name(f".{final.name}.new")    # written aside, then put in place: never a half-written site
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    try:
        pages, seen, written = _write_pages(found, out, figures)
    except BaseException:
        shutil.rmtree(out, ignore_errors=True)
        raise
    names = [p["name"] for p in pages]
    write_json(out / SITE_FILE, {"format": "colonbench-site", "colonbench": __version__,
                                 "inputs": [str(p) for p in paths], "pages": names})
    shutil.rmtree(final, ignore_errors=True)
    out.rename(final)
    return {"index": final / "index.html", "pages": names, "methods": sorted(seen),
            "paths": [final / Path(p).relative_to(out) for p in [*written, out / "index.html", out / SITE_FILE]]}
