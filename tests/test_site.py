"""The leaderboard site (colonbench leaderboard RUN... --out SITE --html), built from a real benchmark folder and
read in headless Chromium."""

import json
import shutil
import sys
from pathlib import Path

import pandas as pd
import pytest

from site_browser import browser, needs_chromium

from colonbench.benchmark import shipped, suites
from colonbench.cli import main

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "constant_method.py"
#: An argument the example program ignores, so that its command line (shown on its method page) holds markup.
MARKUP = "--note=<b>bold</b>&amp;"


@pytest.fixture(scope="module")
def bench(demo_data, tmp_path_factory):
    """A colonbench benchmark --out folder: the example program on demo-v1, the shipped results merged."""
    out = tmp_path_factory.mktemp("site") / "bench"
    assert main(["benchmark", "--methods", f"exec:{sys.executable} {EXAMPLE} '{MARKUP}'", "--suites", "demo-v1",
                 "--data", str(demo_data), "--out", str(out), "--quiet", "--no-figures"]) == 0
    return out


@pytest.fixture(scope="module")
def site(bench):
    out = bench.parent / "site"
    assert main(["leaderboard", str(bench), "--out", str(out), "--html"]) == 0
    return out


@needs_chromium
def test_the_page_of_a_benchmark_folder_in_chromium(site):
    """Done when: the page opens in headless Chromium and shows the suite, the shipped rows and the user's method;
    a click on a header sorts the table."""
    from selenium.webdriver.common.by import By

    tab = pd.read_csv(site / "demo-v1" / "points" / "leaderboard.csv")
    noiseless = tab[tab["noise_mm"] == 0]
    published = set(shipped.load(suites.get("demo-v1"))[0]["methods"])

    def rows(driver, table):
        return [(tr.get_attribute("data-method"), tr.get_attribute("class"))
                for tr in driver.find_elements(By.CSS_SELECTOR, f"#{table} tbody tr")]

    with browser.chromium() as driver:
        driver.get((site / "index.html").as_uri())
        assert driver.title == "colonbench leaderboard"
        summary = [m for m, _ in rows(driver, "summary-noise0")]
        assert set(summary) == published | {"constant_method"}
        driver.find_element(By.CSS_SELECTOR, "#pages a").click()               # follow to the suite's page
        assert driver.title.startswith("demo-v1 · track points")
        assert "Cite as demo-v1 (cbs1-" in driver.find_element(By.TAG_NAME, "body").text
        images = driver.execute_script("return Array.from(document.images).map(i => i.complete && i.naturalWidth)")
        assert len(images) >= 2 and all(images)                                # the figures, loaded from file://
        shown = rows(driver, "coverage-noise0")
        assert [m for m, _ in shown] == list(noiseless["method"])              # ranked as the leaderboard ranks
        assert {m for m, c in shown if c == "shipped"} == published
        assert [m for m, c in shown if c == "mine"] == ["constant_method"]
        mine = driver.find_element(By.CSS_SELECTOR, '#coverage-noise0 tr[data-method="constant_method"]').text
        assert "shipped" not in mine and f"{noiseless.set_index('method').loc['constant_method', 'coverage_mae']:.2f}" \
            in mine
        browser.sort_by(driver, "coverage-noise0", "MAE [95 % CI]")
        ascending = list(noiseless.sort_values("coverage_mae", kind="stable")["method"])
        assert [m for m, _ in rows(driver, "coverage-noise0")] == ascending
        head = [h for h in driver.find_elements(By.CSS_SELECTOR, "#coverage-noise0 th") if h.text.startswith("MAE")]
        assert head[0].get_attribute("aria-sort") == "ascending"
        browser.sort_by(driver, "coverage-noise0", "MAE [95 % CI]")                 # again: descending
        assert [m for m, _ in rows(driver, "coverage-noise0")] == ascending[::-1]
        browser.sort_by(driver, "coverage-noise0", "method")
        assert [m for m, _ in rows(driver, "coverage-noise0")] == sorted(noiseless["method"], key=str.lower)
        driver.find_element(By.LINK_TEXT, "constant_method").click()            # the method's page
        assert MARKUP in driver.find_element(By.TAG_NAME, "body").text         # its command line, as text
        assert not driver.find_elements(By.CSS_SELECTOR, "td b")


def test_a_folder_that_is_not_a_run_is_named(tmp_path, capsys):
    (tmp_path / "notes").mkdir()
    assert main(["leaderboard", str(tmp_path / "notes"), "--out", str(tmp_path / "site"), "--html"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("colonbench: error: ") and str(tmp_path / "notes") in err and "Traceback" not in err
    assert main(["leaderboard", str(tmp_path / "gone"), "--out", str(tmp_path / "site"), "--html"]) == 2
    assert f"{tmp_path / 'gone'}: no such folder" in capsys.readouterr().err
    assert not (tmp_path / "site").exists()


def test_strings_from_runs_are_escaped_and_nothing_comes_from_the_network(site):
    page = (site / "methods" / "constant_method.html").read_text()
    assert "&lt;b&gt;bold&lt;/b&gt;&amp;amp;" in page and "<b>bold" not in page
    assert "None ships" in page and "cpu_count" in page                        # its environment, from run.json
    assert "the shipped model card" in (site / "methods" / "completion.html").read_text()
    for html in site.rglob("*.html"):
        text = html.read_text()
        assert '="http' not in text and "url(" not in text and "@import" not in text, html


def test_a_site_is_rebuilt_in_place_and_never_over_other_files(bench, tmp_path, capsys):
    assert main(["leaderboard", str(bench), "--out", str(bench), "--html"]) == 2   # a folder that is not a site
    assert "holds no site.json" in capsys.readouterr().err
    site = tmp_path / "site"
    assert main(["leaderboard", str(bench), "--out", str(site), "--html", "--no-figures"]) == 0
    (site / "stale.html").write_text("left over")
    assert main(["leaderboard", str(bench / "runs" / "demo-v1"), "--out", str(site), "--html", "--no-figures",
                 "--no-shipped"]) == 0
    assert not (site / "stale.html").exists()
    assert json.loads((site / "site.json").read_text())["pages"] == ["demo-v1/points"]
    assert [p.name for p in (site / "methods").iterdir()] == ["constant_method.html"]


def test_pages_are_per_suite_and_track(bench, tmp_path):
    """A run whose run.json names another track gets its own page, with that track's shipped rows only (none where
    none ship)."""
    other = tmp_path / "length-run"
    shutil.copytree(bench / "runs" / "demo-v1", other, ignore=shutil.ignore_patterns("parts", "predictions"))
    run = json.loads((other / "run.json").read_text())
    (other / "run.json").write_text(json.dumps({**run, "track": "length"}))
    out = tmp_path / "site"
    assert main(["leaderboard", str(bench), str(other), "--out", str(out), "--html", "--no-figures"]) == 0
    assert json.loads((out / "site.json").read_text())["pages"] == ["demo-v1/length", "demo-v1/points"]
    length = pd.read_csv(out / "demo-v1" / "length" / "leaderboard.csv")
    published = shipped.load(suites.get("demo-v1"), track="length")
    assert set(length["method"]) == {"constant_method"} | (set(published[0]["methods"]) if published else set())
    assert "constant_method" in set(pd.read_csv(out / "demo-v1" / "points" / "leaderboard.csv")["method"])
    method = (out / "methods" / "constant_method.html").read_text()
    assert "demo-v1 · track length" in method and "demo-v1 · track points" in method


def test_submitted_results_show_on_the_pages_marked(bench, tmp_path, monkeypatch):
    """A submitted result is a row of its suite's page, marked ‡ and of source submitted, with a method page saying
    so; where a run given has a method of its name, the run's row is shown and the page says the submitted one is
    left out."""
    from colonbench.benchmark import submitted

    monkeypatch.setenv(submitted.ENV, str(tmp_path / "results"))
    submitted.add(bench / "runs" / "demo-v1", "constant_method")
    alone = tmp_path / "alone"          # the shipped results alone, and the submitted ones beside them
    assert main(["benchmark", "--suites", "demo-v1", "--out", str(alone), "--no-figures", "--quiet"]) == 0
    out = tmp_path / "site"
    assert main(["leaderboard", str(alone), "--out", str(out), "--html", "--no-figures"]) == 0
    page = (out / "demo-v1" / "points" / "index.html").read_text()
    assert ('<tr data-method="constant_method" class="submitted"><td data-v="constant_method"><a href="../../methods/'
            'constant_method.html">constant_method</a> ‡</td><td data-v="submitted">') in page
    assert "‡ submitted results" in page and "Left out" not in page
    assert "submitted results (demo-v1/constant_method in the repository" in \
        (out / "methods" / "constant_method.html").read_text()
    assert "none (shipped or submitted results only)" in (out / "index.html").read_text()   # not the runs given
    assert main(["leaderboard", str(bench), "--out", str(out), "--html", "--no-figures"]) == 0
    page = (out / "demo-v1" / "points" / "index.html").read_text()
    assert '<tr data-method="constant_method" class="mine">' in page and 'class="submitted"' not in page
    assert "Left out of this page: submitted constant_method: a method of the runs given has its name." in page
    assert main(["leaderboard", str(alone), "--out", str(out), "--html", "--no-figures", "--no-submitted"]) == 0
    assert "constant_method" not in (out / "demo-v1" / "points" / "index.html").read_text()


def test_the_chart_draws_each_mae_with_its_interval_and_marks_failures():
    """Done when: the headline chart is an SVG (well-formed, so every name is escaped) with a title, an aria-label
    and the axis 'MAE, percentage points'; each method and noise level is a dot inside its interval's bar, placed by
    its MAE; a method with failed samples is marked with the count; a missing MAE says n/a."""
    from xml.etree import ElementTree

    from colonbench.reports.chart import mae_chart

    name = '<b>x</b> & "y"'
    frame = pd.DataFrame({"noise_mm": [0, 0, 0, 0.5, 0.5, 0.5], "method": [name, "plain", "gone"] * 2,
                          "mae": [2.0, 10.0, 5.0, 3.0, 12.0, float("nan")],
                          "mae_lo": [1.0, 8.0, 4.0, 2.0, 9.0, float("nan")],
                          "mae_hi": [3.0, 12.0, 6.0, 4.5, 15.0, float("nan")], "failed": [0, 0, 0, 3, 0, 24]})
    svg = mae_chart(frame, "demo-v1 · points", "chart-demo")
    ns = ""                                     # inline in HTML: the parser gives it the SVG namespace
    root = ElementTree.fromstring(svg)
    assert root.tag == f"{ns}svg" and root.get("role") == "img" and "demo-v1 · points" in root.get("aria-label")
    assert "demo-v1 · points" in root.find(f"{ns}title").text
    texts = ["".join(t.itertext()) for t in root.iter(f"{ns}text")]
    assert "MAE, percentage points" in texts and name in texts and "<b>" not in svg
    assert {"noise sigma = 0 mm", "noise sigma = 0.5 mm"} <= set(texts)
    marks = {(g.get("data-method"), float(g.get("data-noise"))): g for g in root.iter(f"{ns}g")
             if g.get("class", "").startswith("mark")}
    assert set(marks) == set(zip(frame["method"], frame["noise_mm"]))
    for noise, h in frame[frame["mae"].notna()].groupby("noise_mm"):
        xs = []
        for _, r in h.iterrows():
            g = marks[r["method"], noise]
            bar, dot = g.find(f"{ns}line"), g.find(f"{ns}circle")
            x1, x2, cx = float(bar.get("x1")), float(bar.get("x2")), float(dot.get("cx"))
            assert x1 < cx < x2
            xs.append((cx, x1, x2))
        (a, a1, a2), (b, b1, b2) = xs[:2]
        scale = (b - a) / (h["mae"].iloc[1] - h["mae"].iloc[0])           # one linear scale per panel
        hi = (b2 - a2) / (h["mae_hi"].iloc[1] - h["mae_hi"].iloc[0])
        assert scale > 0 and hi == pytest.approx(scale, rel=1e-3)
    failed = marks[name, 0.5]
    assert "failed" in failed.get("class") and "3 failed" in "".join(failed.itertext())
    assert "failed" not in "".join(marks[name, 0.0].itertext()) and "failed" not in marks[name, 0.0].get("class")
    gone = marks["gone", 0.5]
    assert gone.find(f"{ns}circle") is None and "n/a" in "".join(gone.itertext()) and "24 failed" in \
        "".join(gone.itertext())


def test_the_index_shows_the_headline_chart_before_the_tables(site):
    """Done when: the index holds one chart per page, every method of the page on it, before the tables; a suite
    page's figures come before its long tables."""
    index = (site / "index.html").read_text()
    tab = pd.read_csv(site / "demo-v1" / "points" / "leaderboard.csv")
    assert index.count("<svg") == 1 and 'aria-label="Coverage MAE' in index
    assert index.index("<svg") < index.index('id="pages"') < index.index('id="summary-noise0"')
    for _, r in tab.iterrows():
        assert f'data-method="{r["method"]}" data-noise="{r["noise_mm"]:g}"' in index
    page = (site / "demo-v1" / "points" / "index.html").read_text()
    assert page.index("<svg") < page.index("<figure><img") < page.index('id="coverage-noise0"')


def test_a_method_with_failures_is_marked_on_the_chart(bench, demo_data, tmp_path):
    """Done when: a run whose method failed on every segment shows on the index's chart with a failure mark and the
    count, at each noise level; the others have none."""
    import re

    broken = tmp_path / "broken"
    assert main(["evaluate", str(demo_data / "demo-v1"), "--methods", "plugin_methods:Broken", "--out", str(broken),
                 "--quiet"]) == 0
    out = tmp_path / "site"
    assert main(["leaderboard", str(bench), str(broken), "--out", str(out), "--html", "--no-figures"]) == 0
    index = (out / "index.html").read_text()
    marks = {m: c for c, m in re.findall(r'<g class="([^"]*)" data-method="([^"]*)" data-noise="0.5">', index)}
    assert "constant_method" in marks and {m for m, c in marks.items() if c == "mark failed"} == {"broken"}
    assert index.count("✕ 24 failed</text>") == 2


def test_headings_say_percentage_points(site):
    """Done when: no heading, column header, caption, chart text or note says 'points' alone, which a reader could
    take for the points track: it says 'percentage points' (the track reads 'track points')."""
    import re

    for html in site.rglob("*.html"):
        text = html.read_text()
        found = re.findall(r"<(h[1-6]|th|figcaption|caption|text|title|desc)\b[^>]*>(.*?)</\1>", text, re.S) + \
            [("note", t) for t in re.findall(r'<p class="note">(.*?)</p>', text, re.S)]
        for tag, words in found:
            plain = re.sub(r"percentage points|track points|points track", "", re.sub(r"<[^>]+>", "", words))
            assert not re.search(r"\bpoints\b", plain), (html, tag, words)


def test_the_version_string_is_on_the_method_page_not_the_suite_page(site):
    tab = pd.read_csv(site / "demo-v1" / "points" / "leaderboard.csv")
    page = (site / "demo-v1" / "points" / "index.html").read_text()
    version = tab.set_index("method").loc["completion", "version"].iloc[0]
    assert ">version<" not in page and version not in page
    assert version in (site / "methods" / "completion.html").read_text()


@needs_chromium
def test_the_pages_fit_a_1280_px_window(site):
    """Done when: at 1280 px no table of the suite page or the index (its details open) is wider than its container
    and the page needs no horizontal scrollbar; the index's chart is in the first screen."""
    from selenium.webdriver.common.by import By

    tables = """document.querySelectorAll("details").forEach(function (d) { d.open = true; });
      return Array.from(document.querySelectorAll("table")).map(function (t) {
        return [t.id, t.scrollWidth, t.parentElement.clientWidth]; });"""
    with browser.chromium(1280, 900) as driver:
        for page in (site / "demo-v1" / "points" / "index.html", site / "index.html"):
            driver.get(page.as_uri())
            assert driver.execute_script("return window.innerWidth") == 1280
            wide = [t for t in driver.execute_script(tables) if t[1] > t[2]]
            assert not wide, (page, wide)
            assert driver.execute_script("return document.documentElement.scrollWidth") <= 1280, page
            if page.parent.name == "points":
                heads = [h.text for h in driver.find_elements(By.CSS_SELECTOR, "#coverage-noise0 th")]
                assert "MAE [95 % CI]" in heads and "version" not in heads
        chart = driver.find_element(By.CSS_SELECTOR, "svg[role=img]").rect
        assert chart["width"] > 600 and chart["x"] + chart["width"] <= 1280 and 0 < chart["y"] < 900 - 200
