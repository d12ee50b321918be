"""Keep freed memory in the process: glibc's malloc settings for torch on a CPU.

A render chunk or training step allocates and frees arrays of 1-20 MiB many times. glibc serves blocks
that large by mmap and returns them to the kernel on free (its dynamic threshold adapts only partly), so
every new array is first touched page by page: a 256x192 render took 20,000-50,000 page faults, one
sixth of its time on this project's 2-core machine. Raising the mmap and trim thresholds keeps freed
blocks for reuse; the peak memory is unchanged (docs/model.md, "Rendering"). PyTorch's CPU tuning guide
suggests jemalloc or tcmalloc for the same reason; this needs no extra library.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import sys

M_TRIM_THRESHOLD = -1
M_MMAP_THRESHOLD = -3
MMAP_THRESHOLD = 32 * 2**20
"""glibc's upper limit for M_MMAP_THRESHOLD on 64-bit: blocks up to 32 MiB come from the reusable heap."""
TRIM_THRESHOLD = 2**30
"""Free memory kept at the heap's top before it is given back to the kernel."""

_done = False


def keep_freed_memory() -> bool:
    """Apply the settings once per process (glibc only; elsewhere a no-op). True when they are in force."""
    global _done
    if _done:
        return True
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):  # musl and other libcs have no mallopt
        return False
    _done = bool(mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD)) and bool(mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD))
    return _done
