"""The second up estimate (the largest horizontal plane of the points) and its warning (docs/poses.md, World frame)."""

from __future__ import annotations

import numpy as np
import pytest

from stages.poses.up_check import WARN_DEG, UpCheck, check_up


def _room(rng: np.random.Generator) -> np.ndarray:
    """A 4 x 3 m floor (600 points) and two walls 2.5 m high (300 points each), 5 mm of noise, z up."""
    floor = np.column_stack([rng.uniform(-2, 2, 600), rng.uniform(-1.5, 1.5, 600), np.zeros(600)])
    wall_x = np.column_stack([np.full(300, 2.0), rng.uniform(-1.5, 1.5, 300), rng.uniform(0, 2.5, 300)])
    wall_y = np.column_stack([rng.uniform(-2, 2, 300), np.full(300, 1.5), rng.uniform(0, 2.5, 300)])
    return np.concatenate([floor, wall_x, wall_y]) + rng.normal(0, 0.005, (1200, 3))


def _tilted(points: np.ndarray, degrees: float) -> np.ndarray:
    a = np.radians(degrees)  # about the x axis: the floor's normal leaves z by exactly this angle
    turn = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    return points @ turn.T


def test_an_upright_room_passes() -> None:
    check = check_up(_room(np.random.default_rng(1)))
    assert check.plane_tilt_deg is not None and check.plane_tilt_deg < 0.3
    assert check.plane_points >= 550 and check.n_points == 1200  # the floor, less its noisiest points
    assert not check.disagrees and check.warning() is None


@pytest.mark.parametrize("degrees", [3.0, 7.5, 15.0])
def test_a_tilted_world_is_named(degrees: float) -> None:
    check = check_up(_tilted(_room(np.random.default_rng(2)), degrees))
    assert check.plane_tilt_deg == pytest.approx(degrees, abs=0.3)
    warning = check.warning()
    assert warning is not None and f"{degrees:.1f} degrees from the normal of the largest horizontal plane" in warning
    assert "fix: " in warning


def test_a_tilt_within_the_threshold_and_too_few_points_say_nothing() -> None:
    assert not check_up(_tilted(_room(np.random.default_rng(3)), 0.5 * WARN_DEG)).disagrees
    sparse = check_up(_room(np.random.default_rng(4))[:20])
    assert sparse.plane_tilt_deg is None and sparse.warning() is None
    assert check_up(_room(np.random.default_rng(5))).as_dict() == check_up(_room(np.random.default_rng(5))).as_dict()


def test_a_small_floor_among_clutter_is_found_and_a_cloud_without_a_plane_is_not_checked() -> None:
    rng = np.random.default_rng(6)
    # a 4 x 3 m floor of 40 points among 400 scattered through the 4 x 3 x 2.5 m room: 1 in 1,331 triples is floor
    floor = np.column_stack([rng.uniform(-2, 2, 40), rng.uniform(-1.5, 1.5, 40), np.zeros(40)])
    clutter = np.column_stack([rng.uniform(-2, 2, 400), rng.uniform(-1.5, 1.5, 400), rng.uniform(0.2, 2.5, 400)])
    check = check_up(_tilted(np.concatenate([floor, clutter]), 5.0))
    assert check.plane_tilt_deg == pytest.approx(5.0, abs=0.3) and check.plane_points == 40 and check.disagrees
    # the scattered points alone: no plane holds 30 of them within 0.5 % of the room's size (19 mm)
    none = check_up(clutter)
    assert none.plane_tilt_deg is None and 0 < none.plane_points < 30 and none.warning() is None


def test_the_threshold_itself_does_not_warn() -> None:
    assert UpCheck(WARN_DEG, 100, 1000).warning() is None  # "more than 2 degrees" warns
    assert UpCheck(WARN_DEG + 0.01, 100, 1000).warning() is not None
    assert check_up(_room(np.random.default_rng(4))[:20]).plane_points == 0  # too few points: not tried
