"""Chunks rendered on worker threads: the same results, in order, with the caller's torch settings kept."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import torch

from stages.model.chunk_threads import chunk_bounds, map_chunks


@pytest.mark.parametrize("total,chunk", [(49152, 4096), (12288, 4096), (10, 4), (5, 100), (1, 4096), (7, 3)])
def test_chunk_bounds_cover_the_range_in_equal_chunks(total, chunk):
    bounds = chunk_bounds(total, chunk)
    assert bounds[0][0] == 0 and bounds[-1][1] == total
    assert all(stop == start for (_, stop), (start, _) in itertools.pairwise(bounds))
    sizes = [b - a for a, b in bounds]
    assert max(sizes) <= chunk and len(set(sizes[:-1])) <= 1  # equal chunks but the last


def test_no_chunks_for_no_items():
    assert chunk_bounds(0, 4096) == []


def test_chunk_bounds_come_in_fours_whatever_the_workers():
    assert [b - a for a, b in chunk_bounds(49152, 4096)] == [4096] * 12  # a 256x192 view
    assert [b - a for a, b in chunk_bounds(12288, 4096)] == [3072] * 4   # a 128x96 view: 4 chunks, not 3
    assert [b - a for a, b in chunk_bounds(2048, 4096)] == [512] * 4     # one slice of the viewer


def test_map_chunks_keeps_order_grad_mode_and_thread_count():
    x = torch.arange(1000.0)
    threads = torch.get_num_threads()
    seen = []

    def fn(a: int, b: int) -> torch.Tensor:
        seen.append((torch.is_inference_mode_enabled(), torch.is_grad_enabled(), torch.get_num_threads()))
        return x[a:b] * 2

    with torch.inference_mode():
        parts = map_chunks(fn, 1000, 64, 2)
    assert torch.equal(torch.cat(parts), x * 2)
    assert all(s == (True, False, 1) for s in seen)  # the caller's mode, one torch thread per worker
    assert torch.get_num_threads() == threads
    with torch.no_grad():
        map_chunks(fn, 100, 10, 2)
    assert seen[-1][:2] == (False, False)


def test_map_chunks_caps_its_workers(monkeypatch):
    import threading

    from stages.model import chunk_threads

    monkeypatch.setattr(chunk_threads, "MAX_WORKERS", 3)
    names = set()

    def fn(a: int, b: int) -> int:
        names.add(threading.current_thread().name)
        return b - a

    assert sum(map_chunks(fn, 1000, 10, 64)) == 1000
    assert 1 <= len(names) <= 3


def test_map_chunks_raises_a_worker_error():
    def fn(a: int, b: int) -> int:
        if a > 0:
            raise ValueError("chunk failed")
        return b

    with pytest.raises(ValueError, match="chunk failed"):
        map_chunks(fn, 100, 10, 2)


def test_threaded_render_is_bit_identical_to_single_threaded(trained_run):
    from stages.model import load_run

    run = load_run(trained_run)
    rng = np.random.default_rng(0)
    origins, dirs = np.zeros((3000, 3)), rng.normal(size=(3000, 3))
    state = np.full(len(run.objects), 0.5)
    threads = torch.get_num_threads()
    run.config.train.render_chunk = 256  # many chunks, so both workers take several
    try:
        torch.set_num_threads(1)
        single = run.render_rays(origins, dirs, state)
        torch.set_num_threads(2)
        threaded = run.render_rays(origins, dirs, state)
    finally:
        torch.set_num_threads(threads)
    assert set(single) == set(threaded)
    for key in single:  # bit-identical: the chunks are the same whatever the number of workers
        assert np.array_equal(threaded[key], single[key]), key
