"""Headless Chromium for the page tests (tests/test_site.py, tests/test_server_page.py): the driver of
scripts/site_screenshot.py, which drives the system's Chromium through selenium with no network, and the mark that
skips a test where Chromium is not installed."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _script():
    spec = importlib.util.spec_from_file_location("site_screenshot", ROOT / "scripts" / "site_screenshot.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


#: scripts/site_screenshot.py: ``browser.chromium(width, height)`` (a WebDriver, quit on exit), ``browser.sort_by``.
browser = _script()
#: Skips a test where the system's Chromium or chromedriver is missing, saying how to install them.
needs_chromium = pytest.mark.skipif(browser.binaries() is None, reason="Chromium is not installed (apt-get install "
                                    "chromium chromium-driver; scripts/system-deps.sh)")
