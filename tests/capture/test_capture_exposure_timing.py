"""When each render of a blurred or rolled frame is taken, and at which pose and states (docs/captures.md, "Phone
camera effects"): ``FrameRenderer`` drives a renderer that records its calls, so every pose and state is compared
with a hand computation, not with an image.

The spec: one object whose state rises linearly from 0 at the first frame to 1 at the last of 11 (state = frame
position / 10), and a camera walking along x at 3 m/s at 10 fps without hand shake, 0.3 m a frame, at x = 0 at frame
5; in millimetres, so a pose's x at frame position 5 + o is 300 o.
"""

from __future__ import annotations

import numpy as np
import pytest

from stages.capture.camera_effects import FrameRenderer, SensorNoise
from stages.capture.spec import CameraPathSpec, JitterSpec, ScheduleSpec, Units, camera_effects

FRAME = 5


class RecordingRenderer:
    """Stands in for ``SceneRenderer``: returns images whose value is the call's number, and keeps every call."""

    def __init__(self, height: int, width: int) -> None:
        self.h, self.w = height, width
        self.calls: list[tuple[str, np.ndarray, np.ndarray]] = []

    def _out(self) -> dict[str, np.ndarray]:
        k = len(self.calls) - 1  # this call's number, from 0
        return {
            "rgb": np.full((self.h, self.w, 3), float(k), np.float32),
            "depth": np.full((self.h, self.w), k),
            "ids": np.full((self.h, self.w), k),
            "shadow_ids": np.full((1, self.h, self.w), k),
        }

    def render(self, c2w: np.ndarray, states: np.ndarray) -> dict[str, np.ndarray]:
        self.calls.append(("render", np.array(c2w), np.array(states)))
        return self._out()

    def render_rows(self, c2w_rows: np.ndarray, row_states: np.ndarray) -> dict[str, np.ndarray]:
        self.calls.append(("rows", np.array(c2w_rows), np.array(row_states)))
        return self._out()


def _spec(small_spec, height: int = 32):
    spec = small_spec(n_frames=11, width=16, height=height)
    spec.units = Units(name="mm", per_metre=1000.0)
    spec.objects = spec.objects[:1]
    spec.objects[0].schedule = ScheduleSpec(keys=[[0.0, 0.0], [1.0, 1.0]], interpolation="linear")
    spec.camera = CameraPathSpec(
        kind="walk",
        target=[0.0, 1000.0, 0.8],
        waypoints=[[-1.5, -1.0, 0.8], [1.5, -1.0, 0.8]],
        speed_m_s=3.0,
        jitter=JitterSpec(position=0.0, rotation_deg=0.0),
    )
    return spec


def _frame_inputs(spec) -> tuple[np.ndarray, np.ndarray]:
    """Frame 5's pose (mm) and states as generate_capture passes them: x = 0, state 0.5."""
    pose = np.eye(4)
    pose[:3, 3] = [0.0, -1000.0, 800.0]
    return pose, np.array([0.5])


def test_each_exposure_sample_has_the_pose_and_states_of_its_own_time(small_spec):
    spec = _spec(small_spec)
    spec.video.shutter, spec.video.blur_samples = 0.5, 4  # samples at -0.1875, -0.0625, 0.0625, 0.1875 frames
    recorder = RecordingRenderer(32, 16)
    frames = FrameRenderer(spec, recorder)
    out = frames.render(FRAME, *_frame_inputs(spec))
    assert frames.renders_per_frame == len(recorder.calls) == 5  # the sharp centre (masks, depth), then 4 samples
    centre, *samples = recorder.calls
    assert np.array_equal(centre[2], [0.5]) and centre[1][0, 3] == 0.0
    offsets = np.array([-0.1875, -0.0625, 0.0625, 0.1875])
    np.testing.assert_allclose([s[2][0] for s in samples], (FRAME + offsets) / 10, rtol=0, atol=1e-15)
    np.testing.assert_allclose([s[1][0, 3] for s in samples], 300.0 * offsets, rtol=0, atol=1e-9)  # mm
    np.testing.assert_allclose([s[1][1:3, 3] for s in samples], [[-1000.0, 800.0]] * 4, rtol=0, atol=1e-9)
    assert np.all(out["rgb"] == (1 + 2 + 3 + 4) / 4)  # the samples' mean (the centre, call 0, is not one of them)
    assert np.all(out["ids"] == 0) and np.all(out["depth"] == 0)  # masks and depth: the frame's time's


def test_an_odd_sample_count_reuses_the_centre_render(small_spec):
    spec = _spec(small_spec)
    spec.video.shutter, spec.video.blur_samples = 0.6, 3  # samples at -0.2, 0, 0.2: the middle one is the centre
    recorder = RecordingRenderer(32, 16)
    frames = FrameRenderer(spec, recorder)
    out = frames.render(FRAME, *_frame_inputs(spec))
    assert frames.renders_per_frame == len(recorder.calls) == 3
    assert np.all(out["rgb"] == pytest.approx((0 + 1 + 2) / 3))


def test_each_row_of_a_rolling_shutter_has_its_own_pose_and_its_bands_states(small_spec):
    spec = _spec(small_spec, height=32)
    spec.video.rolling_shutter = 0.8  # row r at frame time + (r / 31 - 0.5) x 0.8
    recorder = RecordingRenderer(32, 16)
    FrameRenderer(spec, recorder).render(FRAME, *_frame_inputs(spec))
    ((kind, c2w_rows, row_states),) = recorder.calls
    assert kind == "rows"
    row_time = (np.arange(32) / 31 - 0.5) * 0.8
    np.testing.assert_allclose(c2w_rows[:, 0, 3], 300.0 * row_time, rtol=0, atol=1e-9)  # top row first, in mm
    # 16 bands of 2 rows; band b's states are those of its middle, row 2 b + 0.5
    band_time = ((2 * np.arange(16) + 0.5) / 31 - 0.5) * 0.8
    np.testing.assert_allclose(row_states[:, 0], np.repeat((FRAME + band_time) / 10, 2), rtol=0, atol=1e-15)


def test_a_spec_with_any_one_effect_reports_it():
    """capture.json and truth/spec.yaml keep the effects' keys when any single one is on."""
    from stages.capture import CaptureSpec

    for key, value in (("shutter", 0.5), ("rolling_shutter", 0.5), ("noise_read", 0.01), ("noise_shot", 0.01)):
        spec = CaptureSpec(name="x")
        setattr(spec.video, key, value)
        effects = camera_effects(spec.video)
        assert effects is not None and effects[key] == value, key
    spec = CaptureSpec(name="x")
    spec.video.distortion.p2 = 0.001
    assert camera_effects(spec.video)["distortion"]["p2"] == 0.001
    assert camera_effects(CaptureSpec(name="x").video) is None


@pytest.mark.parametrize(("read", "shot"), [(0.0, 0.01), (0.03, 0.0), (0.02, 0.004)])
def test_sensor_noise_variance_is_read_squared_plus_shot_times_intensity(read, shot):
    """On a flat grey of 0.4, 200,000 draws: the variance read^2 + shot x 0.4 within 2 % (its standard error is
    sqrt(2 / 200000) = 0.3 %), mean 0, and either term alone turns the noise on."""
    from stages.capture import CaptureSpec

    spec = CaptureSpec(name="x")
    spec.video.noise_read, spec.video.noise_shot = read, shot
    noise = SensorNoise(spec)
    assert noise.on
    grey = np.full((200, 1000), 0.4)
    residual = noise(grey) - grey
    expected = read**2 + shot * 0.4
    assert abs(residual.var() / expected - 1) < 0.02
    assert abs(residual.mean()) < 4 * np.sqrt(expected / grey.size)
