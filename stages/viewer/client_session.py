"""One browser tab: its camera, its render loop, and the images sent back to it.

Every client has its own camera, so each gets its own render loop (as in nerfstudio's viewer); the object
states and the relevancy query are shared by all of them and read from the server when a request is made.
Images go back as viser's background image: a preview as JPEG, the full image as lossless PNG, so what
the user sees when the view is still is the run's render, pixel for pixel.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from .render_loop import RenderedFrame, RenderFunction, RenderLoop, RenderRequest
from .view_camera import ViewPose

PREVIEW_JPEG_QUALITY = 85

SceneSettings = Callable[[], tuple[tuple[float, ...], str | None, str]]
"""Returns the shared ``(states, query, source)`` at the moment of a request."""


class ClientSession:
    """Renders for one connected viser client (``viser.ClientHandle``)."""

    def __init__(self, client: Any, render: RenderFunction, settings: SceneSettings, full_pixels: int,
                 frame_budget_s: float, settle_s: float,
                 on_frame: Callable[[int, RenderedFrame], Any] | None = None,
                 on_error: Callable[[int, RenderRequest, BaseException], Any] | None = None) -> None:
        self.client = client
        self.client_id = int(client.client_id)
        self._settings = settings
        self._on_frame = on_frame
        self._on_error = on_error
        self.loop = RenderLoop(render, self._send, full_pixels, frame_budget_s, settle_s,
                               name=f"viewer-render-{self.client_id}", on_error=self._error)
        client.camera.on_update(lambda _camera: self.refresh())

    def view(self) -> ViewPose:
        camera = self.client.camera
        return ViewPose.from_viser(camera.wxyz, camera.position, camera.fov, camera.aspect)

    def refresh(self) -> RenderRequest | None:
        """Ask for a render of the current camera with the current shared settings (latest request wins)."""
        if self.loop.closed:
            return None
        states, query, source = self._settings()
        return self.loop.submit(RenderRequest(view=self.view(), states=states, query=query, source=source))

    def _send(self, frame: RenderedFrame) -> None:
        if frame.final:
            self.client.scene.set_background_image(frame.image, format="png")
        else:
            self.client.scene.set_background_image(frame.image, format="jpeg", jpeg_quality=PREVIEW_JPEG_QUALITY)
        if self._on_frame is not None:
            self._on_frame(self.client_id, frame)

    def _error(self, request: RenderRequest, exc: BaseException) -> None:
        if self._on_error is not None:
            self._on_error(self.client_id, request, exc)

    def close(self) -> None:
        self.loop.close()
