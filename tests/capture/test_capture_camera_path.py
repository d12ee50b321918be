"""Camera paths: an orbit and a walk where the spec puts them, looking at the target, shaken within the jitter."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from stages.capture import load_spec, spec_from_dict
from stages.capture.camera_path import camera_path, camera_poses_at
from stages.scene import look_at

PRESETS = Path(__file__).resolve().parents[2] / "config" / "captures"
STILL = {"position": 0.0, "rotation_deg": 0.0}


def _spec(camera: dict, fps: float, n_frames: int):
    return spec_from_dict({"name": "c", "video": {"fps": fps, "n_frames": n_frames}, "camera": camera})


def test_orbit_positions_follow_start_speed_radius_and_height():
    target = [0.0, 1.2, 0.6]
    spec = _spec(
        {
            "kind": "orbit",
            "target": target,
            "radius": 2.1,
            "height": 1.5,
            "start_deg": -30.0,
            "speed_deg_s": 30.0,
            "jitter": STILL,
        },
        fps=5.0,
        n_frames=6,
    )
    poses = camera_path(spec)
    centres = poses[:, :3, 3]
    # azimuth -30 deg at t = 0, 0 deg (straight on the -y side of the target) at t = 1 s = frame 5
    np.testing.assert_allclose(centres[0], [-2.1 * 0.5, 1.2 - 2.1 * np.sqrt(3) / 2, 1.5], atol=1e-12)
    np.testing.assert_allclose(centres[5], [0.0, 1.2 - 2.1, 1.5], atol=1e-12)
    for pose in poses:  # OpenGL axes: the camera looks down its -z at the target
        view = np.asarray(target) - pose[:3, 3]
        np.testing.assert_allclose(-pose[:3, 2], view / np.linalg.norm(view), atol=1e-12)


def test_walk_moves_at_its_speed_and_stops_at_the_last_waypoint():
    spec = _spec(
        {
            "kind": "walk",
            "target": [0.0, 2.0, 1.0],
            "waypoints": [[-1.0, 0.0, 1.5], [1.0, 0.0, 1.5]],
            "speed_m_s": 0.5,
            "jitter": STILL,
        },
        fps=10.0,
        n_frames=60,
    )
    centres = camera_path(spec)[:, :3, 3]
    # 5 cm a frame along the 2 m line, which it reaches at frame 40; away from the ends smoothing changes nothing
    np.testing.assert_allclose(centres[10], [-0.5, 0.0, 1.5], atol=1e-12)
    np.testing.assert_allclose(centres[20], [0.0, 0.0, 1.5], atol=1e-12)
    np.testing.assert_allclose(centres[45:], np.tile([1.0, 0.0, 1.5], (15, 1)), atol=1e-12)


def test_hand_shake_stays_within_the_jitter_amplitudes():
    camera = {"kind": "orbit", "target": [0.0, 1.0, 0.6], "radius": 2.0, "height": 1.4, "speed_deg_s": 10.0}
    plain = camera_path(_spec({**camera, "jitter": STILL}, fps=10.0, n_frames=30))
    shaky = camera_path(
        _spec({**camera, "jitter": {"position": 0.02, "rotation_deg": 1.0, "frequency_hz": 0.6}}, fps=10.0, n_frames=30)
    )
    offset = shaky[:, :3, 3] - plain[:, :3, 3]
    assert np.abs(offset).max() <= 0.02 + 1e-12  # per axis: a weighted mean of sinusoids x the amplitude
    assert np.abs(offset).max() > 0.005, "the position jitter was not applied"
    turn = [
        np.rad2deg(Rotation.from_matrix(look_at(p[:3, 3], np.array([0.0, 1.0, 0.6]))[:3, :3].T @ p[:3, :3]).magnitude())
        for p in shaky
    ]
    assert max(turn) <= np.sqrt(3) * 1.0 + 1e-9  # at most 1 degree about each of the three axes
    assert max(turn) > 0.25, "the rotation jitter was not applied"


@pytest.mark.parametrize("preset", ["tiny", "study", "laundry"])  # an orbit, two walks (one smoothed over 5 frames)
def test_poses_at_whole_frames_are_the_paths_and_move_smoothly_between(preset):
    spec = load_spec(PRESETS / f"{preset}.yaml")
    path = camera_path(spec)
    n = spec.video.n_frames
    np.testing.assert_allclose(camera_poses_at(spec, np.arange(n)), path, rtol=0, atol=1e-14)
    np.testing.assert_allclose(camera_poses_at(spec, np.array([7.0, 3.0])), path[[7, 3]], rtol=0, atol=1e-14)
    # half a frame on, the camera is between its frames: off their midpoint by the hand shake's curvature only
    # (a 2 cm shake at 0.6 Hz accelerates by up to 0.28 m/s^2: 0.4 mm in half a frame at 10 fps, 2 % of a step)
    mid = camera_poses_at(spec, np.arange(n - 1) + 0.5)[:, :3, 3]
    halfway = (path[:-1, :3, 3] + path[1:, :3, 3]) / 2
    step = np.linalg.norm(np.diff(path[:, :3, 3], axis=0), axis=1)
    assert np.all(np.linalg.norm(mid - halfway, axis=1) <= 0.05 * step)
