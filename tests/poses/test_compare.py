"""livescene poses compare: the similarity it fits recovers a known one; errors show where they are."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from poses_testdata import SMALL_CAMERA, orbit_poses
from scipy.spatial.transform import Rotation

from stages.poses import compare_poses
from stages.poses.cli import main
from stages.scene import write_json
from stages.scene.transforms import camera_to_dict

KNOWN_SCALE = 2.5
KNOWN_R = Rotation.from_rotvec([0.3, -1.1, 0.7]).as_matrix()
KNOWN_T = np.array([4.0, -1.0, 0.5])


def known_sim3() -> np.ndarray:
    s = np.eye(4)
    s[:3, :3] = KNOWN_SCALE * KNOWN_R
    s[:3, 3] = KNOWN_T
    return s


def moved(c2w: np.ndarray) -> np.ndarray:
    """The pose seen in the world mapped by the known similarity (rotation and centre move, no scale)."""
    out = np.eye(4)
    out[:3, :3] = KNOWN_R @ c2w[:3, :3]
    out[:3, 3] = KNOWN_SCALE * KNOWN_R @ c2w[:3, 3] + KNOWN_T
    return out


def write_transforms(path: Path, poses: list[np.ndarray], fx_factor: float = 1.0, first: int = 0) -> Path:
    cam = camera_to_dict(SMALL_CAMERA)
    cam["fl_x"] *= fx_factor
    cam["fl_y"] *= fx_factor
    write_json(path, {**cam, "frames": [{"file_path": f"images/frame_{i:05d}.png", "transform_matrix": p.tolist()}
                                        for i, p in enumerate(poses, start=first)]})
    return path


@pytest.fixture
def truth_poses() -> list[np.ndarray]:
    return orbit_poses(10, arc_deg=50.0)


@pytest.mark.parametrize("align", ["poses", "centres"])
def test_sim3_recovers_a_known_similarity(tmp_path: Path, truth_poses: list[np.ndarray], align: str) -> None:
    truth = write_transforms(tmp_path / "truth.json", truth_poses)
    pred = write_transforms(tmp_path / "pred.json", [moved(p) for p in truth_poses], fx_factor=1.02)
    report = compare_poses(pred, truth, extent=4.0, align=align)
    np.testing.assert_allclose(report["sim3"], known_sim3(), atol=1e-8)
    assert report["scale"] == pytest.approx(KNOWN_SCALE)
    assert report["centre_error_relative"]["max"] < 1e-9
    assert report["rotation_error_deg"]["max"] < 1e-5
    assert report["focal_error"]["relative_fx"] == pytest.approx(0.02)
    assert report["n_matched"] == 10


def test_errors_land_on_the_perturbed_frames(tmp_path: Path, truth_poses: list[np.ndarray]) -> None:
    pred_poses = [moved(p) for p in truth_poses]
    pred_poses[4][:3, :3] = pred_poses[4][:3, :3] @ Rotation.from_rotvec([0.0, 0.0, np.radians(3.0)]).as_matrix()
    pred_poses[7][:3, 3] += KNOWN_SCALE * np.array([0.0, 0.0, 0.08])  # 8 cm in truth units = 2% of a 4 m extent
    truth = write_transforms(tmp_path / "truth.json", truth_poses)
    pred = write_transforms(tmp_path / "pred.json", pred_poses)
    report = compare_poses(pred, truth, extent=4.0)
    per_frame = {f["frame"]: f for f in report["per_frame"]}
    assert per_frame["00004"]["rotation_error_deg"] == pytest.approx(3.0, abs=0.4)
    assert max(f["rotation_error_deg"] for k, f in per_frame.items() if k != "00004") < 0.4
    # least squares spreads part of one outlier over the fit, so the 2% shows as a bit less
    assert 0.014 < per_frame["00007"]["centre_error_relative"] < 0.021
    assert max(f["centre_error_relative"] for k, f in per_frame.items() if k != "00007") < 0.005


def test_cli_prints_and_writes_the_report(tmp_path: Path, truth_poses: list[np.ndarray],
                                          capsys: pytest.CaptureFixture[str]) -> None:
    truth = write_transforms(tmp_path / "truth.json", truth_poses)
    write_json(tmp_path / "scene.json", {"scene_box": [[-2, -1.5, 0], [2, 1.5, 2.5]]})  # extent 4 from the box
    pred = write_transforms(tmp_path / "pred.json", [moved(p) for p in truth_poses[2:]], first=2)
    assert main(["compare", "--pred", str(pred), "--truth", str(truth), "--out", str(tmp_path / "err.json")]) == 0
    printed = capsys.readouterr().out
    assert "frames matched: 8 of 10" in printed and "camera centre error / scene extent (4)" in printed
    report = json.loads((tmp_path / "err.json").read_text())
    assert report["scene_extent"] == 4.0 and report["truth_frames_missing_in_pred"] == ["00000", "00001"]


def test_compare_rejects_files_without_common_frames(tmp_path: Path, truth_poses: list[np.ndarray],
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    truth = write_transforms(tmp_path / "truth.json", truth_poses[:2])
    assert main(["compare", "--pred", str(truth), "--truth", str(truth)]) == 2
    assert "only 2 frame ids in common" in capsys.readouterr().err
