"""glibc's malloc keeps freed blocks for reuse once the model stage has set it up."""

from __future__ import annotations

import platform
import sys

import pytest

from stages.model.allocator import keep_freed_memory


@pytest.mark.skipif(not sys.platform.startswith("linux") or platform.libc_ver()[0] != "glibc",
                    reason="mallopt is glibc's")
def test_glibc_accepts_the_thresholds_and_a_second_call_is_free():
    assert keep_freed_memory() is True
    assert keep_freed_memory() is True
