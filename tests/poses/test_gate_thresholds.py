"""The pose gates at their documented limits (docs/poses.md, "Quality gate"), on camera paths and counts built by
hand: no structure from motion runs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from stages.poses.errors import PoseQualityError
from stages.poses.quality_gate import check_registration, check_trajectory, intrinsics_warnings
from stages.poses.trajectory_check import TrajectorySettings, judge_trajectory


def _names(n: int) -> list[str]:
    return [f"frame_{i:05d}.png" for i in range(n)]


def _line(xs: list[float]) -> np.ndarray:
    return np.array([[x, 0.0, 0.0] for x in xs])


def test_exactly_the_required_share_of_registered_frames_passes(tmp_path: Path) -> None:
    """8 of 10 frames at --min-registered 0.8 is enough ("below the required" refuses); 7 is not."""
    names = _names(10)
    assert check_registration(names, set(names[:8]), 0.8, tmp_path) == pytest.approx(0.8)
    with pytest.raises(PoseQualityError, match="only 7 of 10 frames"):
        check_registration(names, set(names[:7]), 0.8, tmp_path)


def test_a_path_half_of_which_rests_on_one_spot_is_not_mostly_still() -> None:
    """5 cameras on one spot and 5 moving in steps of 0.1 (scene depth 1): the still share is 0.5, which is not
    above max_still_share = 0.5, so the path passes; one more resting camera makes it refused."""
    judged = judge_trajectory(_names(10), _line([0.0] * 5 + [0.1, 0.2, 0.3, 0.4, 0.5]), np.arange(10), 1.0, 10, [10])
    assert judged.still_share == 0.5 and judged.verdict == "pass"
    judged = judge_trajectory(_names(10), _line([0.0] * 6 + [0.1, 0.2, 0.3, 0.4]), np.arange(10), 1.0, 10, [10])
    assert judged.still_share == 0.6 and (judged.verdict, judged.reason) == ("refuse", "mostly still")


def test_a_path_broken_into_two_halves_is_refused_not_trimmed() -> None:
    """Two pieces of 5 cameras 100 depths apart: neither holds a majority of the 10, so no piece may be kept."""
    centres = _line([0.0, 0.1, 0.2, 0.3, 0.4, 100.0, 100.1, 100.2, 100.3, 100.4])
    judged = judge_trajectory(_names(10), centres, np.arange(10), 1.0, 10, [10])
    assert judged.piece_sizes == [5, 5] and (judged.verdict, judged.reason) == ("refuse", "broken path")


def test_a_resting_camera_does_not_shrink_the_typical_step() -> None:
    """The typical step is the median over the steps that move: 20 resting steps and 10 steps of 0.1 give 0.1 (the
    median over all 30 steps would be 0, and the jump limit the floor 0.05 x depth, making every step a jump)."""
    xs = [0.0] * 21 + [0.1 * k for k in range(1, 11)]
    judged = judge_trajectory(_names(31), _line(xs), np.arange(31), 1.0, 31, [31],
                              TrajectorySettings(max_still_share=0.9))
    assert judged.typical_step == pytest.approx(0.1) and judged.jump_limit == pytest.approx(1.0)
    assert judged.verdict == "pass" and judged.trimmed == []


def test_a_camera_far_from_the_middle_of_the_path_is_warned_about(tmp_path: Path) -> None:
    """61 cameras 1 depth apart on a line: the farthest lies 30 depths from the median centre, above the limit 20."""
    settings = TrajectorySettings()
    judged = judge_trajectory(_names(61), _line([float(k) for k in range(61)]), np.arange(61), 1.0, 61, [61],
                              settings)
    assert judged.verdict == "pass" and judged.spread_ratio == pytest.approx(30.0)
    (warning,) = check_trajectory(judged, tmp_path, settings, "fix")
    assert "30.0 median point depths from the middle of the path (limit 20)" in warning


def test_focal_lengths_a_third_apart_are_warned_about() -> None:
    """fx / fy = 130 / 100 = 1.3 lies outside 0.8 .. 1.25 (25 %); fx / fy = 1.2 does not."""
    (warning,) = intrinsics_warnings(130.0, 100.0, 160, 120)
    assert "differ by more than 25%" in warning
    assert intrinsics_warnings(120.0, 100.0, 160, 120) == []
