"""HTML for the leaderboard site (:mod:`colonbench.reports.site`): escaping, cells, sortable tables, pages.

Pages are rendered from the Jinja2 templates in ``templates/`` (:func:`render`;
``page.html`` the skeleton every page extends), with autoescaping: a value
is shown as text unless it comes as :class:`markupsafe.Markup`, which only the
pieces built here and in :mod:`colonbench.reports.chart` are, every string
from a run escaped in them by :func:`esc`. The evaluation server
(:mod:`colonbench.server`) renders its pages from the same templates.

Pages are self-contained: their style and a small table sorter (vanilla
JavaScript, no network) are inline, so they work from ``file://`` and as a
project page. A click on a column header sorts its table, ascending then
descending (numbers by the value in a cell's ``data-v``; missing values last).
"""

from __future__ import annotations

import base64
import hashlib
import re
from functools import lru_cache
from pathlib import Path

import numpy as np
import pandas as pd
from jinja2 import ChoiceLoader, Environment, FileSystemLoader, PackageLoader, StrictUndefined
from markupsafe import Markup, escape

from colonbench._version import __version__

#: Columns holding counts (shown as integers even where a missing value made them floats).
COUNTS = {"segments", "maps", "failed", "failed_maps", "failed_segments", "estimated", "coverage_undefined",
          "interval_segments", "end_unobserved"}
#: Every page's style, inline.
STYLE = """body{font:15px/1.45 system-ui,sans-serif;margin:0 auto;max-width:1600px;padding:1em 2em;color:#222}
table{border-collapse:collapse;margin:.6em 0 1.2em;font-size:13px}th,td{border:1px solid #ccc;padding:3px 6px}
th{background:#eef2f7;cursor:pointer;vertical-align:bottom}td.n{text-align:right}td:first-child{white-space:nowrap}
th[aria-sort=ascending]::after{content:" \\25B2"}th[aria-sort=descending]::after{content:" \\25BC"}
.ci{white-space:nowrap;color:#555}tr.mine td{background:#fff7e0}code,pre{font-size:12px;background:#f4f4f4}
pre{padding:.6em;white-space:pre-wrap}img,svg.chart{max-width:100%;height:auto}.wrap{overflow-x:auto}
.note,figcaption{color:#555;font-size:13px}figure{margin:1em 0 1.5em}
svg.chart{font:12px system-ui,sans-serif;fill:#222}svg.chart .panel{font-weight:600}svg.chart .tick{fill:#555}
svg.chart a text{fill:#1a4f9c}svg.chart text.failed{font-weight:600}"""
#: Every page's table sorter, inline: a click (or Enter) on a header sorts by that column, ascending then descending.
SORTER = """document.querySelectorAll("table.sortable th").forEach(function (th) {
  th.tabIndex = 0; th.addEventListener("click", function () { sortBy(th); });
  th.addEventListener("keydown", function (e) { if (e.key === "Enter") sortBy(th); });
});
function sortBy(th) {
  var table = th.closest("table"), body = table.tBodies[0], col = th.cellIndex;
  var up = th.getAttribute("aria-sort") !== "ascending", num = th.dataset.type === "num";
  table.querySelectorAll("th").forEach(function (h) { h.removeAttribute("aria-sort"); });
  th.setAttribute("aria-sort", up ? "ascending" : "descending");
  var rows = Array.prototype.slice.call(body.rows).map(function (r, i) {
    var c = r.cells[col], v = c ? (c.dataset.v !== undefined ? c.dataset.v : c.textContent.trim()) : "";
    return {r: r, i: i, v: num ? (v === "" ? NaN : parseFloat(v)) : v.toLowerCase()};
  });
  rows.sort(function (a, b) {
    var ma = num ? isNaN(a.v) : a.v === "", mb = num ? isNaN(b.v) : b.v === "";
    if (ma || mb) return ma === mb ? a.i - b.i : (ma ? 1 : -1);  // missing values last, either way
    var d = num ? a.v - b.v : (a.v < b.v ? -1 : a.v > b.v ? 1 : 0);
    return (up ? d : -d) || a.i - b.i;
  });
  rows.forEach(function (x) { body.appendChild(x.r); });
}"""


#: The sorter's hash for a Content-Security-Policy (``script-src 'sha256-...'``): a server that sends one lets the
#: inline sorter run and no other script.
SORTER_SHA256 = "sha256-" + base64.b64encode(hashlib.sha256(SORTER.encode()).digest()).decode()


def esc(x) -> str:
    """``x`` as text safe inside HTML and its attributes (as the templates' autoescaping escapes it)."""
    return str(escape(str(x)))


def inline(text: str) -> str:
    """Escaped text with Markdown's `code` and **bold** (as the leaderboard's sentences use them) as HTML."""
    return re.sub(r"\*\*(.+?)\*\*", r"<b>\1</b>", re.sub(r"`([^`]+)`", r"<code>\1</code>", esc(text)))


def slug(name: str) -> str:
    """A file name for ``name``: itself where it is one, else a cleaned name and a short hash (no collisions)."""
    clean = re.sub(r"[^A-Za-z0-9._-]+", "_", str(name)).strip("._") or "x"
    return clean if clean == name else f"{clean}-{hashlib.sha1(str(name).encode()).hexdigest()[:6]}"


def missing(x) -> bool:
    """None, NA or NaN."""
    return x is None or x is pd.NA or (isinstance(x, (float, np.floating)) and np.isnan(x))


def fmt(x, col: str = "") -> tuple[str, str]:
    """A cell's text and its sort value: counts as integers, seconds to 3 decimals, other numbers to 2."""
    if isinstance(x, (bool, np.bool_)):
        return ("yes" if x else "no"), str(int(x))
    if missing(x):
        return "n/a", ""
    if isinstance(x, (int, np.integer)) or (col in COUNTS and isinstance(x, float) and x.is_integer()):
        return f"{int(x)}", f"{int(x)}"
    if isinstance(x, (float, np.floating)):
        return f"{x:.{3 if col.startswith('seconds') else 2}f}", repr(float(x))
    return str(x), str(x)


def with_interval(r, col: str) -> tuple[str, str]:
    """``value [lo, hi]`` of a column with ``_lo`` and ``_hi`` beside it (a paired difference with its sign)."""
    v, lo, hi = r.get(col), r.get(f"{col}_lo"), r.get(f"{col}_hi")
    if col == "vs_baseline" and r.get("baseline") == r.get("method"):
        return "(best baseline)", "0"
    if missing(v):
        return "n/a", ""
    sign = "+" if col.startswith("vs_") else ""
    ci = "" if missing(lo) or missing(hi) else f" [{lo:{sign}.2f}, {hi:{sign}.2f}]"
    return f"{v:{sign}.2f}{ci}", repr(float(v))


def interval_cell(r, col: str) -> tuple[str, str]:
    """A cell of :func:`with_interval` as HTML: the value, then its interval kept on one line (a narrow column
    wraps between the two)."""
    text, v = with_interval(r, col)
    value, _, ci = text.partition(" [")
    return esc(value) + (f' <span class="ci">[{esc(ci)}</span>' if ci else ""), v


def _attrs(d: dict) -> str:
    return "".join(f' {k}="{esc(v)}"' for k, v in d.items() if v is not None)


def table(tid: str | None, heads: list[tuple[str, bool]], rows: list[tuple[dict, list]]) -> str:
    """A sortable table: ``heads`` (label, numeric); rows (tr attributes, cells of (html, sort value or None))."""
    th = "".join(f'<th scope="col"{_attrs({"data-type": "num" if n else None})}>{esc(h)}</th>' for h, n in heads)
    body = ["<tr" + _attrs(attrs) + ">" + "".join(f'<td{_attrs({"class": "n" if n else None, "data-v": v})}>{c}</td>'
                                                  for (c, v), (_, n) in zip(cells, heads)) + "</tr>"
            for attrs, cells in rows]
    return (f'<div class="wrap"><table class="sortable"{_attrs({"id": tid})}><thead><tr>{th}</tr></thead><tbody>'
            + "\n".join(body) + "</tbody></table></div>")


def kv_table(d: dict) -> str:
    """A two-column table of keys and values (not sortable)."""
    return "<table>" + "".join(f'<tr><th scope="row">{esc(k)}</th><td>{esc(v)}</td></tr>' for k, v in d.items()) + \
        "</table>"


def environment(*folders: str | Path) -> Environment:
    """A Jinja2 environment of the site's templates (this package's ``templates/``), autoescaping.

    Parameters
    ----------
    *folders : str or Path
        Folders of other templates, looked in first (the evaluation server's own pages, which extend
        ``page.html``).

    Returns
    -------
    jinja2.Environment
        Autoescaping, undefined names an error, with ``style``, ``sorter`` and ``version`` (colonbench's) as
        globals.
    """
    loader = PackageLoader("colonbench.reports", "templates")
    if folders:
        loader = ChoiceLoader([FileSystemLoader([str(f) for f in folders]), loader])
    env = Environment(loader=loader, autoescape=True, undefined=StrictUndefined, trim_blocks=True,
                      lstrip_blocks=True, keep_trailing_newline=True)
    env.globals.update(style=Markup(STYLE), sorter=Markup(SORTER), version=__version__)
    return env


@lru_cache(maxsize=1)
def templates() -> Environment:
    """The site's template environment (:func:`environment` of no other folder), made once."""
    return environment()


def render(name: str, **context) -> str:
    """The template ``name`` rendered with ``context``: strings are escaped, :class:`markupsafe.Markup` is not."""
    return templates().get_template(name).render(**context)


def safe(text: str) -> Markup:
    """HTML built here (or in :mod:`colonbench.reports.chart`), every string from a run escaped in it by
    :func:`esc`, marked safe for a template."""
    return Markup(text)


def page(title: str, body: str, root: str) -> str:
    """A whole HTML page (``page.html``): ``body`` is HTML built with :func:`esc`; the style and the table sorter
    inline (no network)."""
    return render("page.html", title=title, body=safe(body), root=root)
