"""The render loop's policy with a stand-in renderer: latest request wins, previews while changing, full when still."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from stages.viewer.render_loop import RenderCancelled, RenderLoop, RenderRequest
from stages.viewer.resolution import Resolution
from stages.viewer.view_camera import ViewPose

FULL = 64 * 48


class ChunkedRender:
    """Renders in ``chunks`` steps of ``step_s`` each, asking ``should_stop`` before every step like FrameRenderer.

    ``gate``: when given, the first render waits for it after its first chunk (to queue requests meanwhile).
    """

    def __init__(self, chunks: int = 4, step_s: float = 0.005, gate: threading.Event | None = None,
                 fail_serial: int | None = None) -> None:
        self.chunks, self.step_s, self.gate, self.fail_serial = chunks, step_s, gate, fail_serial
        self.started: list[int] = []
        self.entered = threading.Event()

    def __call__(self, request: RenderRequest, size: Resolution, should_stop) -> np.ndarray:
        self.started.append(request.serial)
        if request.serial == self.fail_serial:
            raise ValueError("model exploded")
        for i in range(self.chunks):
            if should_stop():
                raise RenderCancelled
            if i == 1 and self.gate is not None and len(self.started) == 1:
                self.entered.set()
                assert self.gate.wait(10)
            time.sleep(self.step_s)
        return np.full((size.height, size.width, 3), request.serial % 256, dtype=np.uint8)


class Delivered:
    def __init__(self) -> None:
        self.frames = []

    def __call__(self, frame) -> None:
        self.frames.append(frame)


def _request(i: float = 0.0) -> RenderRequest:
    return RenderRequest(view=ViewPose(np.eye(4), 1.0, 4 / 3), states=(i,))


@pytest.fixture
def loops():
    made = []
    yield made
    for loop in made:
        loop.close()


def _loop(loops, render, delivered, **kw) -> RenderLoop:
    loop = RenderLoop(render, delivered, FULL, **{"frame_budget_s": 0.15, "settle_s": 0.1, **kw})
    loops.append(loop)
    return loop


def test_an_isolated_change_is_rendered_at_full_resolution_at_once(loops):
    delivered = Delivered()
    loop = _loop(loops, ChunkedRender(), delivered)
    request = loop.submit(_request(0.5))
    assert loop.wait_idle(10)
    assert len(delivered.frames) == 1
    frame = delivered.frames[0]
    assert frame.final and frame.resolution == Resolution(64, 48) and frame.request.serial == request.serial
    assert frame.image.shape == (48, 64, 3) and frame.latency_s >= frame.render_s > 0
    assert loop.stats.finals == 1 and loop.stats.previews == 0 and loop.stats.rays_per_second > 0


def test_the_latest_request_wins_and_cuts_a_full_render_short(loops):
    gate = threading.Event()
    render, delivered = ChunkedRender(gate=gate), Delivered()
    loop = _loop(loops, render, delivered)
    first = loop.submit(_request(0.0))
    assert render.entered.wait(10)  # the first full render is under way
    waiting = [loop.submit(_request(i / 10)) for i in range(1, 6)]
    gate.set()
    assert loop.wait_idle(10)
    last = waiting[-1]
    # the first render stopped at its next chunk; of the five queued requests only the newest was rendered
    assert render.started == [first.serial, last.serial, last.serial]
    assert loop.stats.cancelled == 1
    assert [f.request.serial for f in delivered.frames] == [last.serial, last.serial]
    preview, final = delivered.frames
    assert not preview.final and preview.resolution.pixels < FULL  # it came during a change: a preview first
    assert final.final and final.resolution == Resolution(64, 48)  # then the full image, once still


def test_a_drag_gives_previews_and_one_full_image_when_it_stops(loops):
    delivered = Delivered()
    # settle 1 s: generous, so that a busy machine pausing this thread cannot end the drag early
    loop = _loop(loops, ChunkedRender(step_s=0.01), delivered, settle_s=1.0)
    sent = []
    for i in range(15):  # a drag: a new camera every 20 ms
        sent.append(loop.submit(_request(i / 15)))
        time.sleep(0.02)
    assert loop.wait_idle(10)
    finals = [f for f in delivered.frames if f.final]
    previews = [f for f in delivered.frames if not f.final]
    assert len(finals) == 1 and finals[0].request.serial == sent[-1].serial
    assert previews and all(f.resolution.pixels <= FULL // 4 for f in previews)
    serials = [f.request.serial for f in delivered.frames]
    assert serials == sorted(serials)  # never an older request after a newer one


def test_a_model_fast_enough_skips_previews(loops):
    delivered = Delivered()
    loop = _loop(loops, ChunkedRender(chunks=1, step_s=0.0), delivered, frame_budget_s=1.0, settle_s=0.2)
    loop.submit(_request(0.0))
    assert loop.wait_idle(10)  # measures the speed: FULL pixels in about a millisecond
    for i in range(5):
        loop.submit(_request(i / 5))
        time.sleep(0.01)
    assert loop.wait_idle(10)
    assert delivered.frames and all(f.final for f in delivered.frames)


def test_a_failing_render_is_reported_and_the_loop_goes_on(loops):
    errors = []
    delivered = Delivered()
    loop = _loop(loops, ChunkedRender(fail_serial=1), delivered, on_error=lambda r, e: errors.append((r.serial, e)))
    loop.submit(_request(0.0))
    assert loop.wait_idle(10)
    assert [s for s, _ in errors] == [1] and "model exploded" in str(errors[0][1])
    assert loop.stats.errors == 1 and "ValueError: model exploded" in loop.stats.last_error
    time.sleep(0.15)
    ok = loop.submit(_request(1.0))
    assert loop.wait_idle(10)
    assert [f.request.serial for f in delivered.frames] == [ok.serial]


def test_close_stops_the_thread(loops):
    loop = _loop(loops, ChunkedRender(), Delivered())
    loop.close()
    assert loop.closed and not loop._thread.is_alive()


def test_the_loop_keeps_only_the_newest_frames(loops):
    delivered = Delivered()
    loop = _loop(loops, ChunkedRender(chunks=1, step_s=0.0), delivered)
    for i in range(RenderLoop.RECENT + 6):
        loop.submit(_request(i / 100))
        assert loop.wait_idle(10)
    assert len(delivered.frames) > RenderLoop.RECENT
    assert len(loop.stats.recent) == RenderLoop.RECENT  # a long session does not keep every image it sent
    assert loop.stats.recent == delivered.frames[-RenderLoop.RECENT:]


def test_a_frame_that_cannot_be_delivered_does_not_stop_the_loop(loops):
    """The client may disconnect while its image renders: reported, and the next request is still served."""
    frames = []

    def deliver(frame) -> None:
        if not frames:
            frames.append(None)
            raise ConnectionError("client went away")
        frames.append(frame)

    loop = _loop(loops, ChunkedRender(chunks=1, step_s=0.0), deliver)
    loop.submit(_request(0.0))
    assert loop.wait_idle(10)
    assert loop.stats.errors == 1 and loop.stats.last_error == "deliver: ConnectionError: client went away"
    second = loop.submit(_request(1.0))
    assert loop.wait_idle(10)
    assert frames[-1] is not None and frames[-1].request.serial == second.serial


def test_a_change_during_a_full_render_is_a_preview_even_after_the_settle_time(loops):
    gate = threading.Event()
    render, delivered = ChunkedRender(gate=gate), Delivered()
    loop = _loop(loops, render, delivered, settle_s=0.05, frame_budget_s=1e-9)  # the full image never fits
    loop.submit(_request(0.0))
    assert render.entered.wait(10)
    time.sleep(0.15)  # three settle times after the first request, but the full render still runs
    second = loop.submit(_request(1.0))
    gate.set()
    assert loop.wait_idle(10)
    assert [(f.request.serial, f.final) for f in delivered.frames] == [(second.serial, False), (second.serial, True)]


def test_after_a_preview_the_full_image_waits_for_the_settle_time(loops):
    delivered = Delivered()
    loop = _loop(loops, ChunkedRender(chunks=1, step_s=0.0), delivered, settle_s=0.5, frame_budget_s=1e-9)
    loop.submit(_request(0.0))
    assert loop.wait_idle(10)
    loop.submit(_request(0.5))  # within the settle time: a preview first
    assert loop.wait_idle(10)
    preview, final = delivered.frames[1:]
    assert not preview.final and final.final
    assert final.latency_s >= 0.5  # not rendered before the view was still for settle_s


def test_a_newer_request_does_not_cut_a_preview_short(loops):
    gate, entered, asked = threading.Event(), threading.Event(), []

    def render(request, size, should_stop):
        if size.pixels < FULL:  # the preview: hold it until a newer request waits
            entered.set()
            assert gate.wait(10)
            asked.append(should_stop())
        return np.zeros((size.height, size.width, 3), np.uint8)

    delivered = Delivered()
    loop = _loop(loops, render, delivered, settle_s=0.5, frame_budget_s=1e-9)
    loop.submit(_request(0.0))
    assert loop.wait_idle(10)
    second = loop.submit(_request(0.5))
    assert entered.wait(10)
    loop.submit(_request(1.0))
    gate.set()
    assert loop.wait_idle(10)
    assert asked[0] is False  # while dragging the preview is the only feedback: it always finishes
    assert (second.serial, False) in [(f.request.serial, f.final) for f in delivered.frames]


def test_the_full_image_skips_the_preview_only_when_it_fits_the_frame_budget(loops):
    loop = _loop(loops, ChunkedRender(), Delivered(), frame_budget_s=0.15)
    loop.stats.rays_per_second = FULL / 0.3  # a full image takes 0.3 s: twice the budget
    assert not loop._full_fits_budget()
    loop.stats.rays_per_second = FULL / 0.1
    assert loop._full_fits_budget()
