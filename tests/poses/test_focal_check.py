"""The check that the motion determines the focal length, and its warning (docs/poses.md, "Known focal length")."""

from __future__ import annotations

import math

import numpy as np
import pytest
from colmap_testdata import synthetic_model
from poses_testdata import orbit_poses

from stages.poses import cam_from_world_from_c2w_opengl
from stages.poses.focal_check import FIX, FORWARD_ABOVE, WARN_BELOW_DEG, check_focal, check_model_focal
from stages.scene.camera import look_at


def _cameras(
    eyes: list[tuple[float, float, float]], views: list[tuple[float, float, float]]
) -> tuple[np.ndarray, np.ndarray]:
    """COLMAP cam_from_world rotations of cameras at ``eyes`` looking along ``views``, and their centres."""
    rotations = [
        cam_from_world_from_c2w_opengl(look_at(np.array(e), np.array(e) + np.array(v)))[0]
        for e, v in zip(eyes, views, strict=True)
    ]
    return np.array(rotations), np.array(eyes, dtype=np.float64)


def _yawed(degrees: float) -> tuple[float, float, float]:
    """A horizontal view turned ``degrees`` from +y about z."""
    a = math.radians(degrees)
    return (-math.sin(a), math.cos(a), 0.0)


def test_a_walk_straight_ahead_warns() -> None:
    """Ten cameras walking 1.8 m along +y, all looking along +y: the views do not spread, the path is all forward."""
    rotations, centres = _cameras([(0.0, -1.0 + 0.2 * k, 1.5) for k in range(10)], [(0.0, 1.0, 0.0)] * 10)
    check = check_focal(rotations, centres, 131.0)
    assert check.axis_spread_deg == pytest.approx(0.0, abs=1e-6)
    assert check.forward_share == pytest.approx(1.0)
    assert check.n_cameras == 10 and check.poorly_constrained
    warning = check.warning()
    assert warning is not None and "131.0 px, estimated" in warning and "spread only 0.0 degrees" in warning
    assert "100% of the camera path runs along the view" in warning and warning.endswith(f"fix: {FIX}")
    assert FIX == "give --focal / --focal-35mm (the scene sheet's camera column)"
    record = check.as_dict()
    assert record["poorly_constrained"] is True and record["warn_below_deg"] == WARN_BELOW_DEG


def test_a_sideways_walk_is_not_judged_by_its_spread_alone() -> None:
    """A dolly along x looking along +y: no spread, but a path across the view, whose parallax pins the point depths
    (the walkside capture, 0.9 degrees of spread from hand shake, got its focal within 1 %: docs/poses.md)."""
    rotations, centres = _cameras([(-1.0 + 0.25 * k, -1.0, 1.5) for k in range(9)], [(0.0, 1.0, 0.0)] * 9)
    check = check_focal(rotations, centres, 150.0)
    assert check.axis_spread_deg == pytest.approx(0.0, abs=1e-6) and check.forward_share == pytest.approx(0.0)
    assert not check.poorly_constrained and check.warning() is None


@pytest.mark.parametrize(("yaw", "warns"), [(15.0, False), (9.0, True)])
def test_the_spread_is_the_rms_angle_to_the_mean_view(yaw: float, warns: bool) -> None:
    """Views turned -yaw, 0, +yaw about z: their mean is +y, the angles yaw, 0, yaw, the RMS yaw * sqrt(2/3)
    (12.25 and 7.35 degrees, either side of the threshold); the camera steps along +y, the mean view."""
    rotations, centres = _cameras(
        [(0.0, -0.5, 1.5), (0.0, 0.0, 1.5), (0.0, 0.5, 1.5)], [_yawed(-yaw), _yawed(0.0), _yawed(yaw)]
    )
    check = check_focal(rotations, centres, 150.0)
    assert check.axis_spread_deg == pytest.approx(yaw * math.sqrt(2 / 3), abs=1e-9)
    assert check.forward_share == pytest.approx(1.0)
    assert check.poorly_constrained is warns and (check.warning() is not None) is warns


@pytest.mark.parametrize(("across", "warns"), [(0.9, True), (1.1, False)])
def test_the_forward_share_counts_the_path_along_the_mean_view(across: float, warns: bool) -> None:
    """One step of 1 along the view (+y) and one of ``across`` across it: a share of 1 / (1 + across) forward
    (0.526 and 0.476, either side of the threshold), with the views not spread at all."""
    rotations, centres = _cameras([(0.0, 0.0, 1.5), (0.0, 1.0, 1.5), (across, 1.0, 1.5)], [(0.0, 1.0, 0.0)] * 3)
    check = check_focal(rotations, centres, 150.0)
    assert check.forward_share == pytest.approx(1 / (1 + across))
    assert (check.forward_share > FORWARD_ABOVE) is warns and check.poorly_constrained is warns


def test_a_given_focal_is_not_judged_and_a_refined_one_is() -> None:
    rotations, centres = _cameras([(0.0, -1.0 + 0.2 * k, 1.5) for k in range(5)], [(0.0, 1.0, 0.0)] * 5)
    kept = check_focal(rotations, centres, 150.69, "given")
    assert not kept.poorly_constrained and kept.warning() is None and kept.as_dict()["focal"] == "given"
    refined = check_focal(rotations, centres, 140.3, "given, refined")
    warning = refined.warning()
    assert warning is not None and "140.3 px, given, refined" in warning
    assert warning.endswith("fix: leave out --refine-focal to keep the focal length given")


def test_a_model_of_an_orbit_passes_and_one_of_a_forward_walk_warns() -> None:
    """COLMAP models written from known poses (tests/poses/colmap_testdata.py, focal 100 px): the test data's
    70-degree arc looking across the room, and 12 cameras walking along +y looking at the far wall."""
    names = [f"frame_{k:05d}.png" for k in range(12)]
    orbit = check_model_focal(synthetic_model(names, orbit_poses(12)), names)
    assert orbit.axis_spread_deg > WARN_BELOW_DEG and orbit.forward_share < FORWARD_ABOVE and orbit.warning() is None
    assert orbit.n_cameras == 12 and orbit.focal_px == pytest.approx(100.0)
    walk = [look_at(np.array([0.0, -1.2 + 0.1 * k, 1.2]), np.array([0.0, 1.5, 1.2])) for k in range(12)]
    check = check_model_focal(synthetic_model(names, walk), names[::-1])  # any order: the spread is the same
    assert check.axis_spread_deg == pytest.approx(0.0, abs=1e-6) and check.forward_share == pytest.approx(1.0)
    assert check.n_cameras == 12 and check.warning() is not None
