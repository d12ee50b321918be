"""One CaseContext per test module: the quick settings of `livescene stability --quick`, tiny scenes shared;
torch's thread count is restored afterwards for the tests that follow."""

from __future__ import annotations

import pytest
import torch

from stages.stability import CaseContext


@pytest.fixture(scope="module")
def stability_ctx(tmp_path_factory) -> CaseContext:
    threads = torch.get_num_threads()
    ctx = CaseContext(tmp_path_factory.mktemp("stability"), quick=True, threads=1)
    yield ctx
    torch.set_num_threads(threads)
