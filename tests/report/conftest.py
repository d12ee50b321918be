"""Fixtures of the report tests (helpers in report_browser.py; the chromium fixture is in tests/conftest.py)."""
