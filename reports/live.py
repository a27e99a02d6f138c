"""A hidden suite's leaderboard page, served live by the evaluation server (:mod:`colonbench.server`).

:func:`live_page` renders the static site's suite page (``suite.html``, through
``live.html``) from the public, scored submissions of one hidden suite: the
same skeleton, style and table sorter, the same headline chart
(:mod:`colonbench.reports.chart`) and sortable table
(:mod:`colonbench.reports.webpage`). It takes plain rows, as the server's
``GET /api/v1/suites/SUITE/leaderboard`` answers them, so this package never
imports the server's. Every string of a submission (method, version, team) is
escaped: by the templates' autoescaping, or by :func:`~colonbench.reports.webpage.esc`
where the chart and the table build their HTML.
"""

from __future__ import annotations

from urllib.parse import quote

import pandas as pd

from colonbench.reports.chart import mae_chart
from colonbench.reports.webpage import esc, fmt, render, safe, table

#: The submissions the chart draws, best first (the table lists them all).
CHART_ROWS = 20
#: What the live chart shows, under it: the server keeps each noise level's MAE, not its interval.
CHART_CAPTION = ("Coverage MAE in percentage points of the best public submissions (at most 20), per noise level: a "
                 "dot at the MAE. ✕ n failed: the submission failed on n samples, each scored as the farther of "
                 "coverage 0 and 1 (so counted in the MAE).")


def _mae(x) -> tuple[str, str]:
    text, v = fmt(float("nan") if x is None else float(x))
    return esc(text), v


def _noise_key(x) -> str:
    return f"{float(x):g}"


def chart_frame(rows: list[dict]) -> pd.DataFrame:
    """Rows ``noise_mm``, ``method``, ``mae``, ``mae_lo``, ``mae_hi``, ``failed``, ``kind`` of the first
    :data:`CHART_ROWS` submissions for :func:`colonbench.reports.chart.mae_chart`, each named by its method, team
    and rank (a method may be submitted more than once)."""
    out = []
    for r in rows[:CHART_ROWS]:
        name = f"{r['method']} · {r['team']} (#{r['rank']})"
        for n in r.get("by_noise") or ():
            mae = n.get("coverage_mae")
            out.append({"noise_mm": float(n["noise_mm"]), "method": name,
                        "mae": float("nan") if mae is None else float(mae), "mae_lo": float("nan"),
                        "mae_hi": float("nan"), "failed": n.get("failed") or 0, "kind": "other"})
    return pd.DataFrame(out, columns=["noise_mm", "method", "mae", "mae_lo", "mae_hi", "failed", "kind"])


def board_table(rows: list[dict], noise_mm) -> str:
    """The sortable table of the submissions (id ``leaderboard``): rank, method, version, team, the MAE averaged
    over noise levels and at each, failed samples, when submitted."""
    levels = [_noise_key(n) for n in noise_mm]
    heads = [("rank", True), ("method", False), ("version", False), ("team", False), ("coverage MAE", True)] + [
        (f"MAE at {n} mm", True) for n in levels] + [("failed", True), ("submitted (UTC)", False)]
    body = []
    for r in rows:
        at = {_noise_key(n["noise_mm"]): n for n in r.get("by_noise") or ()}
        failed = sum(int(n.get("failed") or 0) for n in at.values())
        body.append(({"data-method": r["method"], "data-submission": r["id"]}, [
            (esc(r["rank"]), str(r["rank"])), (esc(r["method"]), r["method"]), (esc(r["version"]), r["version"]),
            (esc(r["team"]), r["team"]), _mae(r.get("coverage_mae"))] + [
            _mae(at[n].get("coverage_mae")) if n in at else ("", "") for n in levels] + [
            (esc(failed), str(failed)), (esc(r["submitted_at"]), r["submitted_at"])]))
    return table("leaderboard", heads, body)


def live_page(suite: dict, rows: list[dict], root: str = "/") -> str:
    """The live leaderboard page of a hidden suite.

    Parameters
    ----------
    suite : dict
        ``id``, ``samples`` and ``noise_mm`` of the suite (as ``GET /api/v1/suites`` answers it).
    rows : list of dict
        Its public scored submissions, best first: ``id``, ``rank``, ``method``, ``version``, ``team``,
        ``coverage_mae`` (the mean over noise levels), ``submitted_at`` and ``by_noise`` (per noise level
        ``noise_mm``, ``coverage_mae``, ``failed``), as ``GET /api/v1/suites/SUITE/leaderboard`` answers them.
    root : str
        The server's root URL path (the index of hidden suites), ending in ``/``.

    Returns
    -------
    str
        The HTML page (``live.html``, which extends the static site's ``suite.html``).
    """
    sid = str(suite["id"])
    frame = chart_frame(rows)
    chart = safe(mae_chart(frame, f"{sid} · public submissions", "chart", intervals=False)) if len(frame) else None
    sections = [{"title": "Public submissions", "tables": safe(board_table(rows, suite["noise_mm"])), "id": "board",
                 "note": None, "details": None}] if rows else []
    return render("live.html", title=f"{sid}: colonbench evaluation server", root=root, heading=sid,
                  samples=suite["samples"], noise_levels=", ".join(_noise_key(n) for n in suite["noise_mm"]),
                  chart=chart, chart_caption=CHART_CAPTION, figures=[], sections=sections, rows=rows,
                  json_href=f"{root}api/v1/suites/{quote(sid, safe='')}/leaderboard")
