"""The viser server of ``livescene view``: training-camera frustums, the GUI, the shared scene settings.

Layout of the page (right-hand panel):

- *Object states*: one slider per object of the run, 0 (closed) .. 1 (open), starting at the first frame's
  state; every client sees the same sliders;
- *Language*: a command box ("open the fridge and half open the drawer") whose **Apply** moves the
  sliders, a relevancy query box whose **Show relevancy** replaces colour by the query's map (turbo colour
  map, 0 blue .. 1 red) until **Show colour**, the evidence the map is computed from, and a status line;
- *View*: training cameras on/off (a click on a frustum moves your camera onto it) and the last render's
  size and time.

The 3D view shows the training cameras as frustums (test frames in orange) over the run's render of your
camera, which a background thread per client keeps up to date (render_loop.py).
"""

from __future__ import annotations

import contextlib
import re
import threading
import time
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from stages.scene import InputError, SceneDataset
from stages.scene.dataset import spans_closed_to_open

from .client_session import ClientSession
from .frame_renderer import FrameRenderer
from .language_controls import LanguageControls
from .render_loop import RenderedFrame, RenderRequest
from .view_camera import frustum_scale, look_at_point, scene_up, vertical_fov, viser_pose
from .viser_dependency import require_viser

TRAIN_COLOUR = (40, 90, 220)
TEST_COLOUR = (235, 140, 20)
FRUSTUM_LINE_PX = 1.5
THUMBNAIL_WIDTH = 64
MAX_THUMBNAILS = 400
"""Frustums carry a small image of their frame up to this many frames (each costs a read at start-up)."""


def md_text(text: str) -> str:
    """``text`` (a typed command or query, an object name, an error) shown as itself in a viser markdown element:
    viser renders raw HTML there unsanitised, to every client, and markdown syntax, so an object called
    "<b>drawer" or "kid_s *big* drawer", or a command holding a tag, would be markup."""
    return re.sub(r"([\\`*_\[\]~])", r"\\\1", str(text).replace("&", "&amp;").replace("<", "&lt;"))


def slider_hint(name: str, lo_hi: list[float] | None) -> str:
    """An object slider's tooltip; it names the training frames' range when they do not reach both ends."""
    hint = f"state of {name}: 0 closed, 1 open"
    if lo_hi is not None and not spans_closed_to_open(lo_hi):
        hint += f"; the training frames show {lo_hi[0]:.2f} to {lo_hi[1]:.2f} (beyond, the render extrapolates)"
    return hint


@dataclass(frozen=True)
class ViewerOptions:
    """How the viewer serves and renders (the CLI fills this from its flags)."""

    host: str = "127.0.0.1"
    port: int = 8080
    full_pixels: int = 128 * 96
    """Pixels of a full-resolution render (fitted to each client's aspect)."""
    frame_budget_s: float = 0.15
    """Seconds a preview may take while the view changes."""
    settle_s: float = 0.25
    """Seconds without a change after which the view counts as still (then the full image follows a preview)."""
    chunk_rays: int = 2048
    """Rays per render call: a newer request can stop a full render between two chunks."""
    thumbnails: bool = False
    """Each frustum shows its frame's image (hides the render when the camera sits among the training poses)."""
    verbose: bool = True


class LiveViewer:
    """A running viewer of one trained run; ``stop()`` shuts it down."""

    def __init__(self, run: Any, dataset: SceneDataset, language: LanguageControls,
                 options: ViewerOptions | None = None) -> None:
        viser = require_viser()
        self.run = run
        self.dataset = dataset
        self.language = language
        self.options = options or ViewerOptions()
        self.objects: list[str] = list(run.objects)
        run.check_dataset(dataset)
        self._lock = threading.RLock()
        self._quiet = threading.local()
        self._sessions: dict[int, ClientSession] = {}
        self._listeners: list[Callable[[int, RenderedFrame], Any]] = []
        self.start_frame = (dataset.frames_in("test") or dataset.frames)[0]
        self._states = self._initial_states()
        self._query: str | None = None
        self._source = "probs"
        self.renderer = FrameRenderer(run, language, self.options.chunk_rays)
        self.server = viser.ViserServer(host=self.options.host, port=self.options.port, label="LiveScene",
                                        verbose=self.options.verbose)
        try:
            self._add_scene()
            self._add_gui()
            self.server.on_client_connect(self._connect)
            self.server.on_client_disconnect(self._disconnect)
        except Exception:
            self.server.stop()
            raise

    # -- set-up -------------------------------------------------------------------------------------------------
    def _initial_states(self) -> dict[str, float]:
        frame_index = None
        if [f.frame_id for f in self.dataset.frames] == list(self.run.frame_ids):
            frame_index = self.dataset.frames.index(self.start_frame)
        vector = np.clip(np.nan_to_num(self.run.state_vector(None, frame_index)), 0.0, 1.0)
        return {name: float(v) for name, v in zip(self.objects, vector, strict=True)}

    def _world_centre(self) -> np.ndarray:
        """Centre of the run's scene box in dataset coordinates (the box maps to [-1, 1]^3)."""
        return np.linalg.inv(np.asarray(self.run.norm.transform, dtype=np.float64))[:3, 3].copy()

    def _add_scene(self) -> None:
        ds = self.dataset
        centre = self._world_centre()
        up = scene_up([f.c2w for f in ds.frames])
        self.server.scene.set_up_direction(tuple(float(x) for x in up))
        start = np.asarray(self.start_frame.c2w, dtype=np.float64)
        initial = self.server.initial_camera
        initial.position = tuple(start[:3, 3])
        initial.look_at = tuple(look_at_point(start, centre))
        initial.up = tuple(float(x) for x in up)
        initial.fov = vertical_fov(ds.camera_of(self.start_frame))
        self.frustums: dict[str, Any] = {}
        thumbnails = self.options.thumbnails and len(ds.frames) <= MAX_THUMBNAILS
        scale = frustum_scale(np.stack([np.asarray(f.c2w, dtype=np.float64)[:3, 3] for f in ds.frames]))
        for frame in ds.frames:
            camera = ds.camera_of(frame)
            wxyz, position = viser_pose(frame.c2w)
            image = self._thumbnail(frame) if thumbnails else None
            handle = self.server.scene.add_camera_frustum(
                f"/training_cameras/{frame.frame_id}", fov=vertical_fov(camera), aspect=camera.width / camera.height,
                scale=scale, thickness=FRUSTUM_LINE_PX, thickness_units="screen", image=image, format="jpeg", wxyz=wxyz,
                position=position, color=TEST_COLOUR if frame.split == "test" else TRAIN_COLOUR)
            handle.on_click(self._frustum_clicked(wxyz, position))
            self.frustums[frame.frame_id] = handle

    def _thumbnail(self, frame: Any) -> np.ndarray | None:
        try:
            image = self.dataset.load_image(frame)
        except InputError:
            return None  # a missing image only loses its thumbnail; the frustum is still drawn
        height = max(1, round(image.shape[0] * THUMBNAIL_WIDTH / image.shape[1]))
        small = cv2.resize(image, (THUMBNAIL_WIDTH, height), interpolation=cv2.INTER_AREA)
        return np.clip(small * 255.0 + 0.5, 0, 255).astype(np.uint8)

    @staticmethod
    def _frustum_clicked(wxyz: np.ndarray, position: np.ndarray) -> Callable[[Any], None]:
        def move_camera(event: Any) -> None:
            if event.client is None:
                return
            with event.client.atomic():
                event.client.camera.wxyz = wxyz
                event.client.camera.position = position
        return move_camera

    def _add_gui(self) -> None:
        gui = self.server.gui
        self.sliders: dict[str, Any] = {}
        ranges = self.dataset.state_ranges()
        with gui.add_folder("Object states"):
            self.states_note = gui.add_markdown(
                "" if self.reads_states else f"**Not controllable:** {self.run.STATES_UNREAD}.")
            for name in self.objects:
                slider = gui.add_slider(name, min=0.0, max=1.0, step=0.01, initial_value=round(self._states[name], 2),
                                        hint=slider_hint(name, ranges.get(name)))
                slider.on_update(self._slider_moved(name))
                self.sliders[name] = slider
        with gui.add_folder("Language"):
            self.command_box = gui.add_text("Command", initial_value="",
                                            hint='e.g. "open the fridge", "half open the drawer", "close everything"')
            gui.add_button("Apply command").on_click(lambda _event: self._run_command(self.command_box.value))
            self.query_box = gui.add_text("Relevancy query", initial_value="", hint='a phrase, e.g. "cupboard"')
            self.source_box = gui.add_dropdown("Evidence", options=self.language.sources(), initial_value="probs",
                                               hint="probs: rendered object probabilities; language: the rendered "
                                                    "language embedding (runs trained with language targets)")
            gui.add_button("Show relevancy").on_click(lambda _event: self._show_relevancy(self.query_box.value))
            gui.add_button("Show colour").on_click(lambda _event: self.show_colour())
            self.language_status = gui.add_markdown("")
        with gui.add_folder("View"):
            cameras = gui.add_checkbox("Training cameras", initial_value=True)
            cameras.on_update(lambda _event: self._show_cameras(bool(cameras.value)))
            self.render_status = gui.add_markdown("")

    @property
    def reads_states(self) -> bool:
        """Whether the run's images follow the sliders (``LoadedRun.reads_states``)."""
        return bool(getattr(self.run, "reads_states", True))

    def _show_cameras(self, visible: bool) -> None:
        for handle in self.frustums.values():
            handle.visible = visible

    # -- shared settings ------------------------------------------------------------------------------------------
    def settings(self) -> tuple[tuple[float, ...], str | None, str]:
        """``(states in run.objects order, relevancy query or None, source)`` for a render request."""
        with self._lock:
            return tuple(self._states[o] for o in self.objects), self._query, self._source

    @property
    def states(self) -> dict[str, float]:
        with self._lock:
            return dict(self._states)

    @contextlib.contextmanager
    def _batched(self) -> Iterator[None]:
        """Slider changes made inside (by this thread) do not render one by one: one refresh follows at the end."""
        self._quiet.depth = getattr(self._quiet, "depth", 0) + 1
        try:
            yield
        finally:
            self._quiet.depth -= 1
        self.refresh()

    def _slider_moved(self, name: str) -> Callable[[Any], None]:
        def moved(_event: Any) -> None:
            with self._lock:
                self._states[name] = float(self.sliders[name].value)
            if not getattr(self._quiet, "depth", 0):
                self.refresh()
        return moved

    def set_states(self, values: Mapping[str, float]) -> None:
        """Move the named sliders (every client sees them move) and render once."""
        unknown = sorted(set(values) - set(self.objects))
        if unknown:
            raise InputError("states", f"unknown objects {unknown}", f"use {self.objects}")
        with self._batched():
            for name, value in values.items():
                value = float(np.clip(value, 0.0, 1.0))
                with self._lock:
                    self._states[name] = value
                self.sliders[name].value = value

    def apply_command(self, text: str) -> Any:
        """Parse ``text`` with the project's command grammar and move the sliders; returns the CommandResult."""
        result = self.language.command(text, self.states)
        self.set_states(result.states)
        return result

    def _run_command(self, text: str) -> None:
        text = (text or "").strip()
        if not text:
            self.language_status.content = 'Type a command first, e.g. "open the fridge".'
            return
        if not self.language.encoder_loaded:
            self.language_status.content = f"Running *{md_text(text)}* ..."
        try:
            result = self.apply_command(text)
        except InputError as exc:
            self.language_status.content = f"**Not applied:** {md_text(exc.problem)}. *Fix:* {md_text(exc.fix)}"
            return
        moved = ", ".join(f"{a.object} -> {a.value:.2f} ({a.method})" for a in result.actions)
        unread = "" if self.reads_states else f" (the image does not change: {self.run.STATES_UNREAD})"
        self.language_status.content = f"*{md_text(text)}*: {md_text(moved)}{md_text(unread)}"

    def show_relevancy(self, query: str, source: str | None = None) -> None:
        """Show the relevancy map of ``query`` instead of colour (loads the text encoder the first time)."""
        source = source or str(self.source_box.value)
        self.language.check_source(source)
        self.language.grounder()  # build it here, not in a render thread that should stay responsive
        with self._lock:
            self._query, self._source = query, source
        self.refresh()

    def _show_relevancy(self, query: str) -> None:
        query = (query or "").strip()
        if not query:
            self.language_status.content = 'Type a query first, e.g. "cupboard".'
            return
        if not self.language.encoder_loaded:
            self.language_status.content = "Loading the text encoder ..."
        try:
            self.show_relevancy(query)
        except InputError as exc:
            self.language_status.content = f"**No map:** {md_text(exc.problem)}. *Fix:* {md_text(exc.fix)}"
            return
        match = self.language.grounder().query_match(query)
        nothing = "" if match["object"] else (" It names no object of the scene, so the map shows the object "
                                              "nearest in meaning, not a match.")
        self.language_status.content = f"Relevancy of *{md_text(query)}* ({self._source}): blue 0 .. red 1.{nothing}"

    def show_colour(self) -> None:
        with self._lock:
            self._query = None
        self.language_status.content = ""
        self.refresh()

    # -- clients ---------------------------------------------------------------------------------------------------
    def refresh(self) -> None:
        """Ask every client's loop for a render with the current settings."""
        for session in self.sessions():
            session.refresh()

    def sessions(self) -> list[ClientSession]:
        with self._lock:
            return list(self._sessions.values())

    def add_frame_listener(self, listener: Callable[[int, RenderedFrame], Any]) -> None:
        """Call ``listener(client_id, frame)`` after each image is sent (tests, the benchmark)."""
        self._listeners.append(listener)

    def _connect(self, client: Any) -> None:
        session = ClientSession(client, self.renderer, self.settings, self.options.full_pixels,
                                self.options.frame_budget_s, self.options.settle_s,
                                on_frame=self._frame_sent, on_error=self._render_failed)
        with self._lock:
            self._sessions[session.client_id] = session
        session.refresh()

    def _disconnect(self, client: Any) -> None:
        with self._lock:
            session = self._sessions.pop(int(client.client_id), None)
        if session is not None:
            session.close()

    def _frame_sent(self, client_id: int, frame: RenderedFrame) -> None:
        if frame.final:
            speed = frame.resolution.pixels / frame.render_s
            self.render_status.content = (f"{frame.resolution} in {frame.render_s:.2f} s ({speed / 1000:.0f}k rays/s), "
                                          f"{frame.latency_s:.2f} s after the change")
        for listener in list(self._listeners):
            listener(client_id, frame)

    def _render_failed(self, client_id: int, request: RenderRequest, exc: BaseException) -> None:
        problem = exc.problem if isinstance(exc, InputError) else f"{type(exc).__name__}: {exc}"
        self.render_status.content = f"**Render failed:** {md_text(problem)}"

    def wait_for_clients(self, count: int = 1, timeout: float = 60.0) -> list[ClientSession]:
        """Block until ``count`` clients are connected (tests, the benchmark)."""
        deadline = time.monotonic() + timeout
        while len(self.sessions()) < count:
            if time.monotonic() > deadline:
                raise TimeoutError(f"{len(self.sessions())} of {count} clients connected after {timeout:.0f} s")
            time.sleep(0.05)
        return self.sessions()

    @property
    def port(self) -> int:
        return int(self.server.get_port())

    @property
    def url(self) -> str:
        host = self.options.host if self.options.host not in ("0.0.0.0", "::") else "localhost"
        return f"http://{host}:{self.port}/"

    def stop(self) -> None:
        for session in self.sessions():
            session.close()
        self.server.stop()
