"""The leaderboard's headline as an inline SVG chart: each method's coverage MAE with its 95 % interval.

:func:`mae_chart` draws one figure of a page (a suite, or data, and a track):
one panel per noise level side by side, one row per method, a dot at the MAE
and a bar over its 95 % bootstrap interval, on an x axis in percentage points
shared by the panels. A method with failed samples gets a red mark and the
count beside its bar. The SVG is written here as text (no chart library, no
script, nothing from the network), so it works from ``file://``; it has a
``<title>``, a ``<desc>`` and an ``aria-label``, each mark its own ``<title>``
(a tooltip), and every string in it is escaped. It has no ``xmlns``: inline in
an HTML page, the parser puts it in the SVG namespace.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from colonbench.reports.webpage import esc, missing

#: The colour of a method's mark, by kind (the site's row classes): the runs given, references, the others.
COLOURS = {"mine": "#c0560b", "reference": "#7a7a7a", "other": "#1f5fa8"}
#: The colour of a failure mark.
FAILED = "#c62828"
#: Layout, in px of the viewBox: the whole width, a row, the panels' gap, the space above and below the rows.
WIDTH, ROW, GAP, TOP, BOTTOM = 1180, 22, 40, 40, 46


def ticks(top: float) -> list[float]:
    """Round tick values from 0 to at least ``top`` (4 to 7 of them)."""
    top = top if top > 0 and math.isfinite(top) else 1.0
    step = 10 ** math.floor(math.log10(top / 4))
    for k in (1, 2, 2.5, 5, 10):
        if top / (k * step) <= 6:
            step *= k
            break
    return [float(round(i * step, 10)) for i in range(int(math.ceil(top / step - 1e-9)) + 1)]


def _num(x: float) -> str:
    return f"{round(x, 6):g}"


#: The estimated width of a character of a method's name at 12 px, and the room for the names, least and most.
CHAR, LABELS = 7.2, (110, 260)


def _label_width(labels) -> int:
    """Room for the method names (an estimate of their width), within :data:`LABELS`."""
    return int(min(LABELS[1], max(LABELS[0], CHAR * max(len(str(s)) for s in labels) + 16)))


def _short(label: str, width: int) -> str:
    """``label`` cut to fit ``width`` px, ending in an ellipsis where cut."""
    n = max(4, round((width - 16) / CHAR))
    return label if len(label) <= n else label[:n - 1] + "…"


def _failed_text(r) -> str:
    n = r.get("failed")
    return "" if missing(n) or int(n) == 0 else f"{int(n)} failed"


def _mark(r, y: float, x, kind: str) -> str:
    """One method at one noise level: its bar, its dot, a failure mark and count, and a tooltip."""
    failed = _failed_text(r)
    mae, lo, hi = r["mae"], r.get("mae_lo"), r.get("mae_hi")
    tip = f"{r['method']}, noise {r['noise_mm']:g} mm: " + (
        "MAE n/a" if missing(mae) else f"MAE {mae:.2f}" + ("" if missing(lo) or missing(hi) else
                                                           f" [{lo:.2f}, {hi:.2f}]") + " percentage points") + (
        f"; {failed} (scored as the farther of coverage 0 and 1)" if failed else "")
    cls = "mark failed" if failed else "mark"
    out = [f'<g class="{cls}" data-method="{esc(r["method"])}" data-noise="{r["noise_mm"]:g}">'
           f"<title>{esc(tip)}</title>"]
    colour = COLOURS.get(kind, COLOURS["other"])
    if missing(mae):
        out.append(f'<text x="{x(0) + 4:.1f}" y="{y + 4:.1f}" class="na">n/a</text>')
        end = x(0) + 32
    else:
        a, b = (x(lo), x(hi)) if not (missing(lo) or missing(hi)) else (x(mae) - 1, x(mae) + 1)
        out.append(f'<line x1="{a:.2f}" x2="{b:.2f}" y1="{y:.1f}" y2="{y:.1f}" stroke="{colour}" stroke-width="2"/>'
                   f'<line x1="{a:.2f}" x2="{a:.2f}" y1="{y - 4:.1f}" y2="{y + 4:.1f}" stroke="{colour}"/>'
                   f'<line x1="{b:.2f}" x2="{b:.2f}" y1="{y - 4:.1f}" y2="{y + 4:.1f}" stroke="{colour}"/>'
                   f'<circle cx="{x(mae):.2f}" cy="{y:.1f}" r="4.5" fill="{colour}"/>')
        end = b + 6
    if failed:
        out.append(f'<text x="{end:.1f}" y="{y + 4:.1f}" class="failed" fill="{FAILED}">✕ {esc(failed)}</text>')
    return "".join(out) + "</g>"


def mae_chart(frame: pd.DataFrame, title: str, cid: str, intervals: bool = True) -> str:
    """An SVG chart of the coverage MAE with its 95 % interval: panels per noise level, rows per method.

    Parameters
    ----------
    frame : pandas.DataFrame
        Rows ``noise_mm``, ``method``, ``mae``, ``mae_lo``, ``mae_hi`` (percentage points; NaN where undefined),
        ``failed`` (the samples a method failed on), and where present ``label`` (the name shown, with its marks),
        ``href`` (a link for the name) and ``kind`` (``mine``, ``reference`` or ``other``: the mark's colour).
        Methods are drawn in their order of first appearance.
    title : str
        What the chart shows, for its ``<title>`` and ``aria-label`` (escaped here).
    cid : str
        The SVG's id (its title's and description's ids derive from it).
    intervals : bool
        Whether the frame has intervals, as its title and description say (without: a dot at each MAE, as the
        evaluation server keeps no interval).

    Returns
    -------
    str
        The ``<svg>`` element, to be placed inline in an HTML page.
    """
    methods = list(dict.fromkeys(frame["method"]))
    first = frame.drop_duplicates("method").set_index("method")
    label = {m: str(first["label"].get(m, m)) if "label" in first else m for m in methods}
    noises = sorted(frame["noise_mm"].unique())
    left = _label_width(label.values())
    right = 70 if frame.get("failed", pd.Series(dtype=float)).fillna(0).gt(0).any() else 14
    pw = (WIDTH - left - GAP * (len(noises) - 1)) / len(noises)
    top = np.nanmax(frame[["mae", "mae_lo", "mae_hi"]].to_numpy(float)) if frame["mae"].notna().any() else 1.0
    grid = ticks(top)
    height = TOP + ROW * len(methods) + BOTTOM
    desc = (f"Coverage MAE of {len(methods)} method(s) at noise sigma {', '.join(f'{n:g}' for n in noises)} mm: a "
            f"dot at the MAE{', a bar over its 95 % bootstrap interval' if intervals else ''}, in percentage points; "
            "✕ marks failed samples.")
    name = f"Coverage MAE{' with its 95 % interval' if intervals else ''}, percentage points: {title}"
    out = [f'<svg id="{esc(cid)}" class="chart" role="img" '
           f'viewBox="0 0 {WIDTH} {height}" width="{WIDTH}" height="{height}" aria-label="{esc(name)}" '
           f'aria-describedby="{esc(cid)}-desc"><title>{esc(name)}</title>'
           f'<desc id="{esc(cid)}-desc">{esc(desc)}</desc>']
    for i, m in enumerate(methods):
        y = TOP + ROW * (i + 0.5)
        if i % 2:
            out.append(f'<rect x="0" y="{y - ROW / 2:.1f}" width="{WIDTH}" height="{ROW}" fill="#f5f7fa"/>')
        full = f"<title>{esc(label[m])}</title>" if _short(label[m], left) != label[m] else ""   # a name cut
        text = f'<text x="{left - 8}" y="{y + 4:.1f}" text-anchor="end">{full}{esc(_short(label[m], left))}</text>'
        href = first["href"].get(m) if "href" in first else None
        out.append(f'<a href="{esc(href)}">{text}</a>' if isinstance(href, str) and href else text)
    bottom = TOP + ROW * len(methods)
    for j, noise in enumerate(noises):
        x0 = left + j * (pw + GAP)
        span = pw - right - 6

        def x(v, x0=x0, span=span):
            return x0 + 6 + span * float(v) / grid[-1]

        out.append(f'<text x="{x0 + pw / 2:.1f}" y="{TOP - 22}" text-anchor="middle" class="panel">'
                   f"noise sigma = {noise:g} mm</text>")
        for t in grid:
            out.append(f'<line x1="{x(t):.2f}" x2="{x(t):.2f}" y1="{TOP - 6}" y2="{bottom}" stroke="#dde2ea"/>'
                       f'<text x="{x(t):.2f}" y="{bottom + 15}" text-anchor="middle" class="tick">{_num(t)}</text>')
        out.append(f'<line x1="{x0 + 6}" x2="{x0 + 6}" y1="{TOP - 6}" y2="{bottom}" stroke="#999"/>'
                   f'<text x="{x(grid[-1] / 2):.1f}" y="{bottom + 36}" text-anchor="middle" class="axis">'
                   "MAE, percentage points</text>")
        at = frame[frame["noise_mm"] == noise].drop_duplicates("method").set_index("method")
        for i, m in enumerate(methods):
            if m in at.index:
                r = at.loc[m].to_dict() | {"method": m, "noise_mm": noise}
                out.append(_mark(r, TOP + ROW * (i + 0.5), x, str(r.get("kind", "other"))))
    return "".join(out) + "</svg>"
