"""The live leaderboard page of a hidden suite, end to end: the real server on a loopback port (uvicorn in a
subprocess, a SQLite file, a real worker), uploads through the real client (colonbench submit --wait), then the
suite's page read in headless Chromium, as the static site's page is (tests/test_site.py)."""

from __future__ import annotations

import json

import pytest
from server_fixtures import write_predictions
from server_helpers import Server, colonbench, sample_ids
from site_browser import browser, needs_chromium

pytestmark = pytest.mark.slow

#: A method name that would run script if the page did not escape it (and its server's policy did not stop it).
HOSTILE = '<img src=x onerror="window.pwned=1"><script>window.pwned=2</script><b>bold</b>'


@pytest.fixture(scope="module")
def served(hidden_suite, tmp_path_factory):
    """The server with two public submissions scored through the client: ``(server, suite id, {method: the
    submission as the client printed it})``."""
    sid, private, public, _ = hidden_suite
    base = tmp_path_factory.mktemp("live")
    srv = Server(private, base / "server.db")
    try:
        (base / "token").write_text(srv.token("alpha"))
        got = {}
        for name, coverage in (("mine", 0.5), (HOSTILE, 0.9)):
            preds = write_predictions(base / f"preds-{len(got)}", sample_ids(public), coverage=coverage)
            done = colonbench("submit", "--server", srv.url, "--suite", sid, preds, "--method", name, "--version",
                              "1.0", "--public", "--wait", "--poll", "0.3", "--token-file", base / "token",
                              timeout=240)
            assert done.returncode == 0, done.stderr
            got[name] = json.loads(done.stdout.strip().splitlines()[-1])
            assert got[name]["status"] == "scored"
        yield srv, sid, got
    finally:
        srv.stop()


def test_the_servers_own_pages_extend_the_sites_skeleton(served):
    """The index and the page of an unknown suite: the site's style and sorter, the policy that lets only that
    script run, every name escaped."""
    from colonbench.reports.webpage import SORTER, SORTER_SHA256, STYLE

    srv, sid, _ = served
    for path, status in (("/", 200), ("/suites/%3Cb%3Enone", 404)):
        code, body = srv.get(path)
        page = body.decode()
        assert code == status and f"<style>{STYLE}</style>" in page and f"<script>{SORTER}</script>" in page
        assert "<b>none" not in page
    assert f'<a href="/suites/{sid}">{sid}</a>' in srv.get("/")[1].decode()
    assert "suite &lt;b&gt;none." in srv.get("/suites/%3Cb%3Enone")[1].decode()
    import urllib.request

    with urllib.request.urlopen(f"{srv.url}/suites/{sid}", timeout=60) as r:
        assert f"script-src '{SORTER_SHA256}'" in r.headers["Content-Security-Policy"]


@needs_chromium
def test_the_live_page_shows_the_scored_row_in_chromium(served):
    """Done when: the suite's live page, opened in headless Chromium, shows the scored method's row with its MAE
    (over the noise levels and at each), ranked; a method name with HTML in it is shown as text, and no script of
    it runs; the table sorts (the page's sorter runs under the server's policy) and fits a 1280 px window."""
    from selenium.webdriver.common.by import By

    srv, sid, got = served
    board = {r["method"]: r for r in srv.json("GET", f"/api/v1/suites/{sid}/leaderboard")[1]["rows"]}
    mine = board["mine"]
    assert mine["id"] == got["mine"]["id"] and board[HOSTILE]["id"] == got[HOSTILE]["id"]
    with browser.chromium(1280, 900) as driver:
        driver.get(f"{srv.url}/suites/{sid}")
        assert driver.title == f"{sid}: colonbench evaluation server"
        assert driver.find_element(By.TAG_NAME, "h1").text == sid

        def rows():
            return [(tr.get_attribute("data-submission"), [td.text for td in tr.find_elements(By.TAG_NAME, "td")])
                    for tr in driver.find_elements(By.CSS_SELECTOR, "#leaderboard tbody tr")]

        shown = dict(rows())
        assert set(shown) == {mine["id"], board[HOSTILE]["id"]}
        cells = shown[mine["id"]]
        assert driver.find_element(By.CSS_SELECTOR, f'tr[data-submission="{mine["id"]}"]').is_displayed()
        assert cells[:4] == [str(mine["rank"]), "mine", "1.0", "alpha"]
        assert cells[4] == f"{mine['coverage_mae']:.2f}"
        assert cells[5:7] == [f"{n['coverage_mae']:.2f}" for n in got["mine"]["summary"]]
        assert shown[board[HOSTILE]["id"]][1] == HOSTILE                                  # the name, as text
        assert not driver.find_elements(By.CSS_SELECTOR, "img, b, #leaderboard script")
        assert len(driver.find_elements(By.TAG_NAME, "script")) == 1                      # the sorter alone
        assert driver.execute_script("return window.pwned === undefined")
        marks = driver.find_elements(By.CSS_SELECTOR, "svg.chart g.mark")
        assert {m.get_attribute("data-method").split(" · ")[0] for m in marks} == {"mine", HOSTILE}
        ranked = [i for i, _ in rows()]
        assert ranked == sorted(ranked, key=lambda i: next(r["rank"] for r in board.values() if r["id"] == i))
        browser.sort_by(driver, "leaderboard", "coverage MAE")
        browser.sort_by(driver, "leaderboard", "coverage MAE")                         # again: descending
        assert [i for i, _ in rows()] == ranked[::-1]
        assert driver.execute_script("return document.documentElement.scrollWidth") <= 1280
