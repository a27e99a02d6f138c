"""The leaderboard site's pages come from autoescaping Jinja2 templates (reports/templates/), which the evaluation
server's live suite page renders through as well (colonbench.reports.live); the templates ship in the package."""

from __future__ import annotations

import base64
import fnmatch
import hashlib
import re
from pathlib import Path
from xml.etree import ElementTree

import jinja2
import markupsafe
import pytest

from colonbench.reports import webpage
from colonbench.reports.live import live_page

ROOT = Path(__file__).resolve().parents[1]
#: A string from a submission or a run that would be markup if it were not escaped.
HOSTILE = '<script>window.pwned=1</script><img src=x onerror="window.pwned=2">&amp;\'"'
SUITE = {"id": "tiny-0123456789ab", "samples": 4, "noise_mm": [0.0, 0.5]}


def _row(rank: int, method: str, mae: float, failed: int = 0, **kw) -> dict:
    return {"id": f"sub{rank}", "rank": rank, "method": method, "version": kw.get("version", "1.0"),
            "team": kw.get("team", "alpha"), "coverage_mae": mae, "submitted_at": "2025-01-01T00:00:00Z",
            "by_noise": [{"noise_mm": 0.0, "coverage_mae": mae - 1, "failed": 0},
                         {"noise_mm": 0.5, "coverage_mae": mae + 1, "failed": failed}]}


def test_the_templates_autoescape_and_name_undefined_values():
    env = webpage.templates()
    assert env.autoescape is True
    assert {"page.html", "parts.html", "suite.html", "index.html", "live.html"} <= set(env.list_templates())
    page = webpage.page(HOSTILE, "<p>built with esc: " + webpage.esc(HOSTILE) + "</p>", "")
    assert "<script>window" not in page and "<img" not in page
    assert page.count("&lt;script&gt;window.pwned=1&lt;/script&gt;") == 2          # the title and the body
    assert webpage.esc(HOSTILE) == str(markupsafe.escape(HOSTILE))                  # one escaping, the templates'
    with pytest.raises(jinja2.UndefinedError):                                      # a value forgotten: an error
        webpage.render("suite.html", title="t", root="")


def test_the_live_page_shows_every_submission_string_as_text():
    """Done when: a method, version and team holding markup are shown as text in the table and the chart, and the
    page's only script is the table sorter (its hash the one servers allow)."""
    rows = [_row(1, HOSTILE, 3.0, version=HOSTILE, team=HOSTILE), _row(2, "plain", 5.0, failed=2)]
    page = live_page(SUITE, rows)
    assert "<img" not in page and "window.pwned=1</script>" not in page
    scripts = re.findall(r"<script>(.*?)</script>", page, re.S)
    assert scripts == [webpage.SORTER]
    assert webpage.SORTER_SHA256 == "sha256-" + base64.b64encode(hashlib.sha256(scripts[0].encode()).digest()).decode()
    svg = ElementTree.fromstring(re.search(r"<svg.*?</svg>", page, re.S).group(0))   # well-formed: names escaped
    texts = ["".join(t.itertext()) for t in svg.iter("title")]
    assert any(t.startswith(HOSTILE + " · ") for t in texts)                         # the full name, as text
    assert "95 % interval" not in svg.get("aria-label")                            # the server keeps none
    row = re.search(r'<tr data-method="([^"]*)" data-submission="sub1">(.*?)</tr>', page, re.S)
    assert row.group(1) == webpage.esc(HOSTILE) and row.group(2).count(webpage.esc(HOSTILE)) >= 6   # text, sort key
    assert '<td class="n" data-v="3.0">3.00</td>' in row.group(2)                  # the MAE over noise levels
    assert "✕ 2 failed" in page


def test_the_live_page_is_the_static_sites_suite_page():
    """The live page extends the static site's suite.html: the same style, sorter, chart figure and sortable
    table; with no submission it says so and draws no chart."""
    page = live_page(SUITE, [_row(1, "mine", 2.5)])
    assert f"<style>{webpage.STYLE}</style>" in page and '<figure class="chart"><svg' in page
    assert '<table class="sortable" id="leaderboard">' in page and 'href="/api/v1/suites/tiny-0123456789ab/' in page
    assert "evaluation server" in page and "colonbench leaderboard RUN" not in page
    empty = live_page(SUITE, [])
    assert "No public submission is scored yet." in empty and "<svg" not in empty and "<table" not in empty


def test_the_templates_are_package_data():
    """Every template file of reports/ and server/ matches the package data of its package in pyproject.toml, so a
    wheel carries it (an editable install reads the folders)."""
    tomllib = pytest.importorskip("tomllib")
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    folders = {pkg: folder for pkg, folder in config["package-dir"].items()}
    for pkg in ("colonbench.reports", "colonbench.server"):
        base = ROOT / folders[pkg]
        files = [p.relative_to(base).as_posix() for p in (base / "templates").rglob("*") if p.is_file()]
        assert files
        globs = config["package-data"].get(pkg, [])
        missing = [f for f in files if not any(fnmatch.fnmatch(f, g) for g in globs)]
        assert not missing, f"{pkg}: not package data: {missing}"
    deps = [re.split(r"[<>=\[; ]", d)[0].lower() for d in
            tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["dependencies"]]
    assert "jinja2" in deps and "markupsafe" in deps                                  # the static site needs them
