"""A phone camera's imperfections in the video frames: motion blur, rolling shutter and sensor noise (the lens's
distortion is in ``lens.py``; docs/captures.md, "Phone camera effects").

Each is off by default, and off it costs nothing and changes no byte: a frame is then the one render at the
frame's pose and states it always was. Time here is a frame position: video frame i at i, a sub-frame exposure
or a sensor row at a fraction of a frame interval beside it (``camera_poses_at`` and ``states_at`` take these).
"""

from __future__ import annotations

import numpy as np

from .camera_path import camera_poses_at, seeded_rng
from .renderer import SceneRenderer
from .spec import CaptureSpec, VideoSpec
from .state_schedule import states_at

ROLLING_STATE_BANDS = 16
"""Under a rolling shutter each row has the camera pose of its time, but the object states change per band of
rows (this many per frame, each at its middle row's time): a ray-casting scene is built per state, and 240 a frame
would cost more than the frame's rays (a scene takes ~1 ms, 16 of them ~0.1 of a 320x240 render). A door that
turns 100 degrees in two seconds turns 3 degrees during a readout of 0.6 at 10 fps: 0.19 degrees a band."""


def exposure_offsets(video: VideoSpec) -> np.ndarray:
    """The sub-frame times of one exposure (frame intervals from the frame's time): the middles of ``blur_samples``
    equal slices of [-shutter / 2, shutter / 2], so the exposure is centred on the frame's time."""
    n = video.blur_samples
    return ((np.arange(n) + 0.5) / n - 0.5) * video.shutter


def row_offsets(video: VideoSpec, rows: np.ndarray | None = None) -> np.ndarray:
    """When each sensor row (or fractional row: a band's middle) is exposed, in frame intervals from the frame's
    time: the top row first, the middle row (of an odd height; between the two middle rows of an even one) at the
    frame's time. ``rows`` defaults to every row of the image."""
    rows = np.arange(video.height) if rows is None else rows
    return (rows / (video.height - 1) - 0.5) * video.rolling_shutter


class FrameRenderer:
    """Renders a spec's video frames through its camera's shutter: blurred, rolled, or the one sharp render."""

    def __init__(self, spec: CaptureSpec, renderer: SceneRenderer) -> None:
        self.spec = spec
        self.renderer = renderer
        v = spec.video
        self.offsets = exposure_offsets(v) if v.shutter > 0 else np.zeros(1)
        self.rows = row_offsets(v) if v.rolling_shutter > 0 else None
        h = v.height
        bands = np.arange(h) * min(ROLLING_STATE_BANDS, h) // h  # band of each row
        starts = np.flatnonzero(np.r_[True, bands[1:] != bands[:-1]])
        ends = np.r_[starts[1:], h]
        self._band_of_row = bands
        self._band_middle = (starts + ends - 1) / 2.0  # a band's middle row (fractional for an even band)

    @property
    def renders_per_frame(self) -> int:
        """Full renders per video frame (the centre one for masks and depth, plus the exposure's samples)."""
        blurred = len(self.offsets) > 1
        return 1 + (len(self.offsets) - int(0.0 in self.offsets) if blurred else 0)

    def _render_at(self, i: int, offset: float, pose: np.ndarray, states: np.ndarray) -> dict[str, np.ndarray]:
        """Frame i's image ``offset`` frame intervals from its time; ``pose`` and ``states`` are the frame's own."""
        spec = self.spec
        if self.rows is None:
            if offset == 0.0:
                return self.renderer.render(pose, states)
            c2w = camera_poses_at(spec, np.array([i + offset]))[0]
            c2w[:3, 3] *= spec.units.per_metre
            return self.renderer.render(c2w, states_at(spec, np.array([i + offset]))[0])
        c2w_rows = camera_poses_at(spec, i + offset + self.rows)
        c2w_rows[:, :3, 3] *= spec.units.per_metre
        middle_times = i + offset + row_offsets(spec.video, self._band_middle)
        row_states = states_at(spec, middle_times)[self._band_of_row]
        return self.renderer.render_rows(c2w_rows, row_states)

    def render(self, i: int, pose: np.ndarray, states: np.ndarray) -> dict[str, np.ndarray]:
        """Frame i (``pose`` in output units and ``states`` at its time): ``rgb`` averaged over the exposure;
        ``ids``, ``depth`` and ``shadow_ids`` at the frame's time (through the rolling shutter's rows when there is
        one), where its truth pose is."""
        centre = self._render_at(i, 0.0, pose, states)
        if len(self.offsets) == 1:
            return centre
        total = np.zeros(centre["rgb"].shape, dtype=np.float64)
        for offset in self.offsets:
            total += centre["rgb"] if offset == 0.0 else self._render_at(i, float(offset), pose, states)["rgb"]
        return {**centre, "rgb": (total / len(self.offsets)).astype(np.float32)}


class SensorNoise:
    """Gaussian sensor noise of standard deviation sqrt(noise_read^2 + noise_shot x intensity), in the frame's linear
    intensity after its exposure gain, before 8-bit rounding; drawn from its own seeded stream in frame order."""

    def __init__(self, spec: CaptureSpec) -> None:
        self.read = spec.video.noise_read
        self.shot = spec.video.noise_shot
        self.rng = seeded_rng(spec.seed, "sensor-noise")

    @property
    def on(self) -> bool:
        return self.read > 0 or self.shot > 0

    def __call__(self, rgb: np.ndarray) -> np.ndarray:
        x = np.asarray(rgb, dtype=np.float64)
        std = np.sqrt(self.read**2 + self.shot * np.clip(x, 0.0, None))
        return x + std * self.rng.standard_normal(x.shape)
