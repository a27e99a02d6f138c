"""The leaderboard site's pages come from autoescaping Jinja2 templates (reports/templates/); the templates ship in
the package."""

from __future__ import annotations

import fnmatch
import re
from pathlib import Path

import jinja2
import markupsafe
import pytest

from colonbench.reports import webpage

ROOT = Path(__file__).resolve().parents[1]
#: A string from a submission or a run that would be markup if it were not escaped.
HOSTILE = '<script>window.pwned=1</script><img src=x onerror="window.pwned=2">&amp;\'"'


def test_the_templates_autoescape_and_name_undefined_values():
    env = webpage.templates()
    assert env.autoescape is True
    assert {"page.html", "parts.html", "suite.html", "index.html"} <= set(env.list_templates())
    page = webpage.page(HOSTILE, "<p>built with esc: " + webpage.esc(HOSTILE) + "</p>", "")
    assert "<script>window" not in page and "<img" not in page
    assert page.count("&lt;script&gt;window.pwned=1&lt;/script&gt;") == 2          # the title and the body
    assert webpage.esc(HOSTILE) == str(markupsafe.escape(HOSTILE))                  # one escaping, the templates'
    with pytest.raises(jinja2.UndefinedError):                                      # a value forgotten: an error
        webpage.render("suite.html", title="t", root="")


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
