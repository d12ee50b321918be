"""Rendering chunks of rays on several CPU threads at once, each thread running torch single-threaded.

torch splits each op over its intra-op threads, which pays for large ops only: a render chunk's many small
ops, and ``grid_sample`` (parallel over the 3 planes of a stack: 2 rounds on 2 threads), leave cores idle.
Handing whole chunks to worker threads instead keeps every core busy (torch ops release the GIL). Each
chunk is still computed by one thread in the same order of ops, so results depend neither on which worker
took it nor on how many there are; docs/model.md ("Rendering on a CPU") has the measurements.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

import torch

T = TypeVar("T")


MAX_WORKERS = 16
"""Worker threads at most: each holds a chunk's intermediate arrays (~100 MiB at 4096 rays of cpu-demo), so a
many-core machine does not multiply that by its core count."""
SPLIT = 4
"""Chunks per render come in multiples of this: balanced on 1, 2 or 4 workers, and the same on every machine."""


def chunk_bounds(total: int, chunk: int) -> list[tuple[int, int]]:
    """``[start, stop)`` of equal chunks of at most ``chunk`` items, as many as a multiple of ``SPLIT``.

    The split does not depend on the number of workers: a chunk's result depends on its size (matrix
    products block by it), so a render is bit-identical whatever the machine's core count.
    """
    if total <= 0:
        return []
    n = math.ceil(math.ceil(total / max(chunk, 1)) / SPLIT) * SPLIT
    size = math.ceil(total / n)
    return [(i, min(i + size, total)) for i in range(0, total, size)]


def map_chunks(fn: Callable[[int, int], T], total: int, chunk: int, workers: int) -> list[T]:
    """``fn(start, stop)`` over the chunks of ``range(total)``, in order, on ``workers`` threads (at most MAX_WORKERS).

    Workers run torch ops on one thread each and inherit the caller's grad and
    inference mode (both are thread-local in torch). The caller's thread count
    is restored afterwards.
    """
    bounds = chunk_bounds(total, chunk)
    workers = min(workers, MAX_WORKERS, len(bounds))
    if workers <= 1:
        return [fn(a, b) for a, b in bounds]
    grad, inference = torch.is_grad_enabled(), torch.is_inference_mode_enabled()
    previous = torch.get_num_threads()

    def work(bound: tuple[int, int]) -> T:
        torch.set_num_threads(1)  # this worker's ops; the process-wide default is put back below
        with torch.inference_mode(inference), torch.set_grad_enabled(grad):
            return fn(*bound)

    try:
        with ThreadPoolExecutor(max_workers=workers, thread_name_prefix="render-chunk") as pool:
            return list(pool.map(work, bounds))
    finally:
        torch.set_num_threads(previous)
