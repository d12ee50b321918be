"""Tiny captures generated at test time (a few seconds), shared across the capture tests."""

from __future__ import annotations

from pathlib import Path

import pytest
from tiny_capture_spec import small_spec

from stages.capture import generate_capture


@pytest.fixture(name="small_spec")
def small_spec_fixture():
    """The ``small_spec`` factory, for tests that need their own spec."""
    return small_spec


@pytest.fixture(scope="session")
def tiny_capture(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("capture") / "tiny"
    return generate_capture(small_spec(), out, progress=False)
