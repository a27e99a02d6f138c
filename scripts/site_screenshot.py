"""A page of the leaderboard site in headless Chromium, sorted by a column if asked, as a PNG.

docs/leaderboard-page.png is the site's front page, its headline chart in view, in a 1280 x 900 window:

    colonbench benchmark --methods "exec:python examples/constant_method.py" --suites demo-v1 --out runs/try
    colonbench leaderboard runs/try --out site --html
    python scripts/site_screenshot.py site/index.html --out docs/leaderboard-page.png

A suite's page, sorted: ``python scripts/site_screenshot.py site/demo-v1/points/index.html --sort "MAE [95 % CI]"
--out page.png``.

It drives the system's Chromium (``apt-get install chromium chromium-driver``, as scripts/system-deps.sh does)
through selenium and the system's chromedriver, never a downloaded driver, with no network: the flags below keep
Chromium from trying connections on a machine without internet. tests/test_site.py drives it the same way.
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
from contextlib import contextmanager
from pathlib import Path

#: Chromium's command-line flags: headless, no sandbox (root in a container), no GPU, nothing on the network.
FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync", "--hide-scrollbars")


def binaries() -> tuple[str, str] | None:
    """The system's Chromium and chromedriver, or None where either is missing."""
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    driver = shutil.which("chromedriver") or ("/usr/bin/chromedriver" if Path("/usr/bin/chromedriver").is_file()
                                              else None)
    return (chromium, driver) if chromium and driver else None


@contextmanager
def chromium(width: int = 1280, height: int = 1000):
    """A selenium WebDriver of headless Chromium with a fresh profile, quit (and its profile removed) on exit."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    found = binaries()
    if found is None:
        raise RuntimeError("Chromium is not installed: apt-get install chromium chromium-driver "
                           "(scripts/system-deps.sh)")
    profile = tempfile.mkdtemp(prefix="colonbench-chromium-")
    options = webdriver.ChromeOptions()
    options.binary_location = found[0]
    for flag in FLAGS + (f"--user-data-dir={profile}", f"--window-size={width},{height}"):
        options.add_argument(flag)
    driver = webdriver.Chrome(service=Service(executable_path=found[1]), options=options)
    try:
        yield driver
    finally:
        driver.quit()
        shutil.rmtree(profile, ignore_errors=True)


def sort_by(driver, table_id: str, label: str) -> None:
    """Click the header ``label`` of the table ``table_id`` on the open page."""
    from selenium.webdriver.common.by import By

    heads = driver.find_elements(By.CSS_SELECTOR, f"#{table_id} th")
    match = [h for h in heads if h.text.strip() == label]
    if not match:
        raise SystemExit(f"no column {label!r} in #{table_id}; its columns: {[h.text for h in heads]}")
    match[0].click()


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("page", type=Path, help="an HTML page of a site (colonbench leaderboard ... --html)")
    ap.add_argument("--out", type=Path, required=True, help="PNG to write")
    ap.add_argument("--sort", help="click this column header of the first noise level's table first")
    ap.add_argument("--table", default="coverage-noise0", help="the table --sort clicks in (default coverage-noise0)")
    ap.add_argument("--width", type=int, default=1280)
    ap.add_argument("--height", type=int, default=900)
    args = ap.parse_args(argv)
    with chromium(args.width, args.height) as driver:
        driver.get(args.page.resolve().as_uri())
        if args.sort:
            sort_by(driver, args.table, args.sort)
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_bytes(driver.get_screenshot_as_png())
    print(f"wrote {args.out} ({args.out.stat().st_size // 1024} KiB)")


if __name__ == "__main__":
    main()
