"""One client's render thread: the latest request wins, a preview while the view changes, the full image when still.

Policy (nerfstudio's viewer does the same with a state machine and a trace hook that aborts renders; this
one cancels between ray chunks instead):

- every change (camera, slider, command, query) is a ``submit``; only the newest waiting request is kept;
- a request that arrives while the view is changing continuously (less than ``settle_s`` after the previous
  one, or while a full render was running) is first rendered as a *preview* sized to render in about
  ``frame_budget_s`` at the measured speed, unless the full image fits in that budget anyway (CUDA);
- an isolated change (a slider clicked once, the first camera message) is rendered at full resolution at once;
- after a preview, the full image follows when no request came for ``settle_s``;
- a full render stops between two ray chunks when a newer request is waiting (a preview always finishes:
  it is short, and while dragging it is the only feedback the user gets).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from .resolution import Resolution, fit_to_aspect, preview_pixels
from .view_camera import ViewPose

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class RenderRequest:
    """What to show: the client's view and the shared scene settings at the moment of a change."""

    view: ViewPose
    states: tuple[float, ...]
    query: str | None = None
    """Relevancy query; None renders colour."""
    source: str = "probs"
    """Evidence of the relevancy map (stages.language.grounding): probs, language or language_objects."""
    serial: int = 0
    submitted: float = 0.0
    """``time.perf_counter()`` when the loop received it (set by ``RenderLoop.submit``)."""


@dataclass(frozen=True)
class RenderedFrame:
    """One image handed to the client."""

    request: RenderRequest
    image: np.ndarray
    """uint8 ``[H, W, 3]`` RGB."""
    resolution: Resolution
    final: bool
    """Full resolution (True) or a preview (False)."""
    render_s: float
    latency_s: float
    """From ``submit`` of the request to the image being ready."""


class RenderCancelled(Exception):
    """Raised by a render function whose ``should_stop`` turned true (a newer request is waiting)."""


RenderFunction = Callable[[RenderRequest, Resolution, Callable[[], bool]], np.ndarray]
"""``render(request, resolution, should_stop) -> uint8 [H, W, 3]``; raises RenderCancelled when told to stop."""


@dataclass
class LoopStats:
    """Counters of one render loop (shown in the status line, read by tests and the benchmark)."""

    submitted: int = 0
    previews: int = 0
    finals: int = 0
    cancelled: int = 0
    errors: int = 0
    last_error: str | None = None
    rays_per_second: float | None = None
    recent: list[RenderedFrame] = field(default_factory=list)


class RenderLoop:
    """Renders one client's requests in a daemon thread and hands each image to ``deliver``."""

    RECENT = 64

    def __init__(self, render: RenderFunction, deliver: Callable[[RenderedFrame], Any], full_pixels: int,
                 frame_budget_s: float = 0.15, settle_s: float = 0.25, name: str = "viewer-render",
                 on_error: Callable[[RenderRequest, BaseException], Any] | None = None) -> None:
        self._render = render
        self._deliver = deliver
        self._on_error = on_error
        self.full_pixels = int(full_pixels)
        self.frame_budget_s = float(frame_budget_s)
        self.settle_s = float(settle_s)
        self.stats = LoopStats()
        self._cond = threading.Condition()
        self._pending: RenderRequest | None = None
        self._pending_burst = False
        self._due: RenderRequest | None = None
        self._last_arrival = -float("inf")
        self._in_full = False
        self._busy = False
        self._closed = False
        self._serial = 0
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    # -- requests ---------------------------------------------------------------------------------------------
    def submit(self, request: RenderRequest) -> RenderRequest:
        """Queue ``request`` in place of any request still waiting; returns it with its serial and time."""
        now = time.perf_counter()
        with self._cond:
            self._serial += 1
            request = replace(request, serial=self._serial, submitted=now)
            # part of a continuous change: close on the heels of the previous request, or cutting a full render
            burst = (now - self._last_arrival) < self.settle_s or self._in_full
            self._pending_burst = burst or (self._pending is not None and self._pending_burst)
            self._pending = request
            self._last_arrival = now
            self.stats.submitted += 1
            self._cond.notify_all()
        return request

    def close(self, timeout: float = 5.0) -> None:
        with self._cond:
            self._closed = True
            self._cond.notify_all()
        self._thread.join(timeout)

    @property
    def closed(self) -> bool:
        return self._closed

    def wait_idle(self, timeout: float = 30.0) -> bool:
        """Block until nothing is waiting, rendering or due (tests and the benchmark); False on timeout."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while self._pending is not None or self._due is not None or self._in_full or self._busy:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    return False
                self._cond.wait(min(remaining, 0.05))
        return True

    # -- the thread ---------------------------------------------------------------------------------------------
    def _full_fits_budget(self) -> bool:
        speed = self.stats.rays_per_second
        return bool(speed) and self.full_pixels / speed <= self.frame_budget_s

    def _next(self) -> tuple[RenderRequest, bool] | None:
        """Wait for the next job: (request, final) or None when closed."""
        with self._cond:
            while True:
                if self._closed:
                    return None
                if self._pending is not None:
                    request, burst = self._pending, self._pending_burst
                    self._pending, self._pending_burst = None, False
                    final = not burst or self._full_fits_budget()
                    self._due = None if final else request
                    self._busy = True
                    self._in_full = final
                    return request, final
                if self._due is not None:
                    wait_s = self._last_arrival + self.settle_s - time.perf_counter()
                    if wait_s <= 0:
                        request, self._due = self._due, None
                        self._busy = self._in_full = True
                        return request, True
                    self._cond.wait(wait_s)
                else:
                    self._cond.wait()

    def _should_stop_full(self) -> bool:
        return self._closed or self._pending is not None

    def _should_stop_preview(self) -> bool:
        return self._closed

    def _run(self) -> None:
        while (job := self._next()) is not None:
            request, final = job
            try:
                self._render_one(request, final)
            finally:
                with self._cond:
                    self._busy = self._in_full = False
                    self._cond.notify_all()

    def _render_one(self, request: RenderRequest, final: bool) -> None:
        if final:
            size = fit_to_aspect(self.full_pixels, request.view.aspect)
        else:
            pixels = preview_pixels(self.full_pixels, self.stats.rays_per_second, self.frame_budget_s)
            size = fit_to_aspect(pixels, request.view.aspect)
        start = time.perf_counter()
        try:
            image = self._render(request, size, self._should_stop_full if final else self._should_stop_preview)
        except RenderCancelled:
            self.stats.cancelled += 1
            return
        except Exception as exc:  # a failing render must not kill the client's loop: report it and go on
            self.stats.errors += 1
            self.stats.last_error = f"{type(exc).__name__}: {exc}"
            log.exception("viewer render failed")
            if self._on_error is not None:
                self._on_error(request, exc)
            return
        done = time.perf_counter()
        seconds = max(done - start, 1e-6)
        speed = size.pixels / seconds
        prev = self.stats.rays_per_second
        self.stats.rays_per_second = speed if prev is None else 0.5 * prev + 0.5 * speed
        frame = RenderedFrame(request=request, image=image, resolution=size, final=final, render_s=seconds,
                              latency_s=done - request.submitted)
        if final:
            self.stats.finals += 1
        else:
            self.stats.previews += 1
        self.stats.recent = [*self.stats.recent[-(self.RECENT - 1):], frame]
        try:
            self._deliver(frame)
        except Exception as exc:  # e.g. the client disconnected while we rendered
            self.stats.errors += 1
            self.stats.last_error = f"deliver: {type(exc).__name__}: {exc}"
            log.warning("viewer could not deliver a frame: %s", exc)
