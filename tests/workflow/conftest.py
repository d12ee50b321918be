"""Fixtures of the workflow tests (helpers in workflow_copy.py)."""

from __future__ import annotations

from pathlib import Path

import pytest
from workflow_copy import WorkflowCopy


@pytest.fixture
def workflow_copy(tmp_path: Path) -> WorkflowCopy:
    return WorkflowCopy(tmp_path / "wf")
