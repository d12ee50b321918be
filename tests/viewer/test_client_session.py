"""One browser tab without a browser: a stand-in viser client, its camera read into the request, images sent back."""

from __future__ import annotations

import math

import numpy as np

from stages.viewer.client_session import PREVIEW_JPEG_QUALITY, ClientSession
from stages.viewer.render_loop import RenderedFrame, RenderRequest
from stages.viewer.resolution import Resolution
from stages.viewer.view_camera import ViewPose, rotation_to_wxyz


class FakeCamera:
    def __init__(self) -> None:
        self.wxyz = rotation_to_wxyz(np.diag([1.0, -1.0, -1.0]))  # OpenCV axes of an OpenGL identity pose
        self.position = np.array([1.0, 2.0, 3.0])
        self.fov = math.radians(50)
        self.aspect = 16 / 9
        self.callbacks = []

    def on_update(self, callback) -> None:
        self.callbacks.append(callback)


class FakeScene:
    def __init__(self) -> None:
        self.images = []

    def set_background_image(self, image, format, jpeg_quality=None) -> None:
        self.images.append((image.shape, format, jpeg_quality))


class FakeClient:
    client_id = 7

    def __init__(self) -> None:
        self.camera, self.scene = FakeCamera(), FakeScene()


def _blank(request, size, should_stop) -> np.ndarray:
    return np.zeros((size.height, size.width, 3), np.uint8)


def test_a_camera_update_renders_that_camera_and_the_full_image_goes_back_as_png():
    client, frames = FakeClient(), []
    session = ClientSession(
        client,
        _blank,
        lambda: ((0.25, 1.0), None, "probs"),
        full_pixels=16 * 9 * 4,
        frame_budget_s=0.15,
        settle_s=0.01,
        on_frame=lambda cid, f: frames.append((cid, f)),
    )
    try:
        assert len(client.camera.callbacks) == 1
        client.camera.callbacks[0](client.camera)  # the browser moved its camera
        assert session.loop.wait_idle(10)
        ((cid, frame),) = frames
        assert cid == 7 and frame.final and frame.request.states == (0.25, 1.0)
        view = frame.request.view
        assert view.fov_y == math.radians(50) and view.aspect == 16 / 9
        expected = np.eye(4)
        expected[:3, 3] = [1.0, 2.0, 3.0]
        assert np.allclose(view.c2w, expected, atol=1e-12)
        assert frame.resolution == Resolution(32, 18)  # 576 pixels at 16:9
        assert client.scene.images == [((18, 32, 3), "png", None)]
        # a preview travels as JPEG
        preview = RenderedFrame(
            request=frame.request,
            image=np.zeros((9, 16, 3), np.uint8),
            resolution=Resolution(16, 9),
            final=False,
            render_s=0.01,
            latency_s=0.01,
        )
        session._send(preview)
        assert client.scene.images[-1] == ((9, 16, 3), "jpeg", PREVIEW_JPEG_QUALITY)
    finally:
        session.close()
    assert session.refresh() is None  # a closed tab asks for nothing


def test_the_request_carries_the_shared_query_and_source():
    client = FakeClient()
    session = ClientSession(
        client, _blank, lambda: ((0.0,), "cupboard", "language"), full_pixels=64, frame_budget_s=0.15, settle_s=0.01
    )
    try:
        request = session.refresh()
        assert isinstance(request, RenderRequest) and request.query == "cupboard" and request.source == "language"
        assert isinstance(request.view, ViewPose)
    finally:
        session.close()
