"""Fixtures of the report tests (helpers in report_browser.py)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from report_browser import Chromium


@pytest.fixture
def chromium(tmp_path: Path):
    binary = shutil.which("chromium") or shutil.which("chromium-browser")
    if binary is None:
        pytest.skip("Debian chromium is not installed (apt-get install chromium)")
    browser = Chromium(binary, tmp_path / "chromium-profile")
    try:
        browser.open_page()
        yield browser
    finally:
        browser.close()
