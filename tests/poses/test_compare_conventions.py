"""``livescene poses compare`` on cases whose answer is known without running it: frames of another size, and a
mirrored world that no similarity can undo."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from poses_testdata import SMALL_CAMERA, orbit_poses

from stages.poses import compare_poses
from stages.scene import InputError, write_json
from stages.scene.transforms import camera_to_dict


def _write(path: Path, poses: list[np.ndarray], camera: dict) -> Path:
    write_json(path, {**camera, "frames": [{"file_path": f"images/frame_{i:05d}.png", "transform_matrix": p.tolist()}
                                           for i, p in enumerate(poses)]})
    return path


def test_the_focal_length_of_frames_extracted_at_half_size_is_compared_at_the_reference_size(tmp_path: Path) -> None:
    """Estimated on 80x60 frames with fx = fy = 50: at the reference's 160x120 that is 100, the reference's focal."""
    poses = orbit_poses(6, arc_deg=50.0)
    half = camera_to_dict(SMALL_CAMERA.scaled(0.5))
    report = compare_poses(_write(tmp_path / "pred.json", poses, half),
                           _write(tmp_path / "truth.json", poses, camera_to_dict(SMALL_CAMERA)), extent=4.0)
    focal = report["focal_error"]
    assert focal["pred_fx_at_truth_size"] == pytest.approx(100.0)
    assert focal["pred_fy_at_truth_size"] == pytest.approx(100.0)
    assert focal["relative_fx"] == pytest.approx(0.0) and focal["relative_fy"] == pytest.approx(0.0)


def test_a_mirrored_world_is_not_aligned_away(tmp_path: Path) -> None:
    """Poses mirrored in x (centres (-x, y, z); each camera mirrored too, so its rotation stays proper) are no
    similarity of the originals (a similarity has a proper rotation and a positive scale): the comparison must not
    undo the mirror with an improper fit and report a perfect match. On this arc no proper fit has a positive scale
    either, so it is refused."""
    poses = orbit_poses(8, arc_deg=120.0)
    flip = np.diag([-1.0, 1.0, 1.0, 1.0])
    camera = camera_to_dict(SMALL_CAMERA)
    pred = _write(tmp_path / "pred.json", [flip @ p @ flip for p in poses], camera)
    with pytest.raises(InputError, match="no similarity aligns the camera centres") as err:
        compare_poses(pred, _write(tmp_path / "truth.json", poses, camera), extent=4.0)
    # the cameras do move: the message names the mirror, not coinciding centres
    assert "mirror image" in str(err.value) and "check that the cameras move" not in str(err.value)


def test_cameras_that_do_not_move_are_named_as_such(tmp_path: Path) -> None:
    """Every camera at one centre (a tripod turning in place): no similarity is defined by the centres."""
    poses = orbit_poses(8, arc_deg=120)
    for p in poses:
        p[:3, 3] = [0.5, -0.2, 1.0]
    camera = camera_to_dict(SMALL_CAMERA)
    with pytest.raises(InputError, match=r"degenerate configuration.*check that the cameras move"):
        compare_poses(_write(tmp_path / "pred.json", poses, camera), _write(tmp_path / "truth.json", poses, camera),
                      extent=4.0)
