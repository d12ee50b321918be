"""A known focal length (`livescene poses --focal` / `--focal-35mm`): converted, checked, given to COLMAP and kept."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from stages.poses import PosesConfig, estimate_poses
from stages.poses.cli import main
from stages.poses.known_focal import known_focal
from stages.scene import Camera, InputError

Room = tuple[Path, Path, Camera, list[np.ndarray]]


def test_35mm_equivalent_is_converted_by_the_image_diagonal() -> None:
    # 4000x3000 frames have a diagonal of 5000 px; 26 mm of a 43.27 mm full-frame diagonal is 26 / 43.27 of it
    focal = known_focal(None, 26.0, False, 4000, 3000, Path("frames"))
    assert focal is not None and focal.focal_px == pytest.approx(3004.3910, abs=1e-3)
    assert focal.given == "--focal-35mm 26" and not focal.refine
    # the same lens on frames shrunk to a quarter: a quarter of the pixels
    quarter = known_focal(None, 26.0, False, 1000, 750, Path("frames"))
    assert quarter is not None and quarter.focal_px == pytest.approx(751.0978, abs=1e-3)


def test_pixels_are_taken_as_given_with_the_principal_point_at_the_centre() -> None:
    focal = known_focal(110.0, None, True, 160, 120, Path("frames"))
    assert focal is not None and focal.focal_px == 110.0 and focal.refine
    assert focal.camera_params("RADIAL") == "110.0,80.0,60.0,0.0,0.0"  # f, cx, cy, k1, k2
    assert focal.camera_params("SIMPLE_PINHOLE") == "110.0,80.0,60.0"
    assert focal.camera_params("OPENCV") == "110.0,110.0,80.0,60.0,0.0,0.0,0.0,0.0"
    assert focal.camera_params("SIMPLE_RADIAL") == "110.0,80.0,60.0,0.0"  # f, cx, cy, k
    assert focal.camera_params("PINHOLE") == "110.0,110.0,80.0,60.0"  # fx, fy, cx, cy
    assert focal.as_dict()["refined"] is True and focal.as_dict()["given"] == "--focal 110"
    # the diagonal of 160x120 is 200 px: 100 px each side of the centre at 110 px, atan(100 / 110) = 42.27 deg
    assert focal.as_dict()["diagonal_fov_deg"] == pytest.approx(84.55, abs=0.01)
    assert known_focal(None, None, False, 160, 120, Path("frames")) is None


@pytest.mark.parametrize(
    ("px", "mm", "refine", "words"),
    [
        (100.0, 26.0, False, "both --focal 100 and --focal-35mm 26"),
        (0.0, None, False, "0 is not a positive focal length"),
        (None, -26.0, False, "-26 is not a positive focal length"),
        (None, None, True, "--refine-focal without a focal length"),
        (5.0, None, False, "diagonal field of view of 174.3 degrees"),  # 2 * atan(100 / 5)
        (1e5, None, False, "diagonal field of view of 0.1 degrees"),
        (None, 2.0, False, "diagonal field of view of 169.4 degrees"),  # 2 * atan(21.635 / 2)
        (float("nan"), None, False, "nan is not a positive focal length"),
        (16.73, None, False, "diagonal field of view of 161.0 degrees"),  # 2 * atan(100 / 16.73): just above 160
        (12732.0, None, False, "diagonal field of view of 0.9 degrees"),  # 2 * atan(100 / 12732): just below 1
    ],
)
def test_contradictions_and_absurd_values_are_refused(
    px: float | None, mm: float | None, refine: bool, words: str
) -> None:
    with pytest.raises(InputError, match="fix: ") as info:
        known_focal(px, mm, refine, 160, 120, Path("frames"))
    assert words in str(info.value)


@pytest.mark.parametrize(("px", "fov"), [(18.53, 159.0), (10417.0, 1.1)])
def test_values_just_inside_the_field_of_view_limits_are_taken(px: float, fov: float) -> None:
    # the 160x120 frames' half diagonal is 100 px: 2 * atan(100 / 18.53) = 159.0, 2 * atan(100 / 10417) = 1.1 degrees
    focal = known_focal(px, None, False, 160, 120, Path("frames"))
    assert focal is not None and focal.as_dict()["diagonal_fov_deg"] == pytest.approx(fov, abs=0.01)


def test_cli_refuses_before_anything_is_written(
    room_sequence: Room, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    root = room_sequence[0]
    out = tmp_path / "poses"
    assert main(["--frames", str(root), "--out", str(out), "--focal", "3", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "--focal 3 px gives the 160x120 frames a diagonal field of view of 176.6 degrees" in err
    assert "pixels of the frames as written" in err and not out.exists()


def test_a_given_focal_is_kept_and_recorded(room_sequence: Room, tmp_path: Path) -> None:
    """The rendered room's focal is 100 px; given 104 px (4 % off), COLMAP keeps it exactly (with the poses and
    distortion fitted around it) and both outputs say it was given."""
    root, masks, _camera, _poses = room_sequence
    out = tmp_path / "poses"
    summary = estimate_poses(
        PosesConfig(frames_dir=root, out_dir=out, masks_dir=masks, threads=2, seed=0, focal_px=104.0, progress=False)
    )
    transforms = json.loads((out / "transforms.json").read_text())
    assert transforms["fl_x"] == 104.0 and transforms["cx"] == 80.0 and transforms["cy"] == 60.0
    assert transforms["focal_given"]["focal_px"] == 104.0 and transforms["focal_given"]["given"] == "--focal 104"
    assert transforms["focal_given"]["refined"] is False
    assert summary["camera"]["params"][0] == 104.0 and summary["camera"]["focal_given"] == transforms["focal_given"]
    assert summary["registered_fraction"] == 1.0
    # a focal kept as given is not judged by the focal check (docs/poses.md, "Known focal length")
    assert summary["focal_check"]["focal"] == "given" and summary["focal_check"]["focal_px"] == 104.0
    assert summary["focal_check"]["poorly_constrained"] is False


def test_a_refined_focal_far_from_the_given_one_is_warned_of() -> None:
    focal = known_focal(100.0, None, True, 160, 120, Path("frames"))
    assert focal is not None
    assert focal.refined_warning(80.0) is None and focal.refined_warning(125.0) is None  # the bounds: 0.8, 1.25
    warning = focal.refined_warning(58.4)
    assert warning is not None and "(--focal 100: 100.0 px) to 58.4 px (-42 %)" in warning and "fix: " in warning
    assert "(+26 %)" in str(focal.refined_warning(126.0))
    kept = known_focal(100.0, None, False, 160, 120, Path("frames"))
    assert kept is not None and kept.refined_warning(58.4) is None  # kept as given: nothing moved it


def test_a_given_focal_with_refine_is_refined_and_its_drift_named(room_sequence: Room, tmp_path: Path) -> None:
    """--refine-focal from 104 px (the rendered focal is 100 px): bundle adjustment moves it, here to 58.4 px
    (measured: docs/poses.md, Known focal length), and the summary's warnings say so."""
    root, masks, _camera, _poses = room_sequence
    out = tmp_path / "poses"
    summary = estimate_poses(PosesConfig(frames_dir=root, out_dir=out, masks_dir=masks, threads=2, seed=0,
                                         focal_px=104.0, refine_focal=True, progress=False))
    transforms = json.loads((out / "transforms.json").read_text())
    assert transforms["focal_given"]["refined"] is True and transforms["focal_given"]["focal_px"] == 104.0
    assert transforms["fl_x"] != 104.0  # refined, not kept
    warned = any(w.startswith("--refine-focal moved the given focal length (--focal 104: 104.0 px)")
                 for w in summary["warnings"])
    assert warned == (not 0.8 * 104.0 <= transforms["fl_x"] <= 1.25 * 104.0)  # here 58.4 px: warned
