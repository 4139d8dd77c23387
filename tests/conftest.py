"""Shared fixtures: one headless Chromium per test module (Debian's /usr/bin/chromium,
driven by Playwright; never `playwright install`)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--no-first-run", "--disable-extensions"]


@pytest.fixture(scope="module")
def browser():
    """A headless Chromium for the whole module. Locally it is skipped, with the reason,
    only when Debian's chromium is absent; in CI (CI=true) that is a failure."""
    if not CHROMIUM.exists():
        message = f"{CHROMIUM} is absent: `apt-get install chromium` (Debian's; browsers are not downloaded)"
        if os.environ.get("CI"):
            pytest.fail(message)
        pytest.skip(message)
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS, headless=True)
        try:
            yield b
        finally:
            b.close()
