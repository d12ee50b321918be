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
    assert "only 2 frames match the reference" in capsys.readouterr().err


def write_named(path: Path, poses: list[np.ndarray], names: list[str | None], extra: dict | None = None) -> Path:
    """A transforms.json whose frames carry ``names`` as file_path (None: no file_path, only colmap_im_id)."""
    frames = []
    for k, (name, pose) in enumerate(zip(names, poses, strict=True)):
        frame: dict = {"transform_matrix": pose.tolist(), "colmap_im_id": k + 1}
        if name is not None:
            frame["file_path"] = name
        frames.append(frame)
    write_json(path, {**camera_to_dict(SMALL_CAMERA), "frames": frames, **(extra or {})})
    return path


def write_colmap_model(folder: Path, poses: list[np.ndarray], names: list[str]) -> Path:
    """A COLMAP model (cameras/images/points3D .bin) holding ``poses`` under the image ``names``."""
    import pycolmap

    from stages.poses import cam_from_world_from_c2w_opengl

    rec = pycolmap.Reconstruction()
    c = SMALL_CAMERA
    rec.add_camera_with_trivial_rig(pycolmap.Camera(model="PINHOLE", width=c.width, height=c.height,
                                                    params=[c.fx, c.fy, c.cx, c.cy], camera_id=1))
    for k, (name, c2w) in enumerate(zip(names, poses, strict=True)):
        rotation, translation = cam_from_world_from_c2w_opengl(c2w)
        pose = pycolmap.Rigid3d(rotation=pycolmap.Rotation3d(rotation), translation=translation)
        rec.add_image_with_trivial_frame(pycolmap.Image(name=name, camera_id=1, image_id=k + 1), pose)
    folder.mkdir(parents=True)
    rec.write(str(folder))
    return folder


def frames_stage_names(ids: list[int]) -> list[str | None]:
    return [f"images/frame_{i:05d}.png" for i in ids]


def assert_exact(report: dict, n: int) -> None:
    assert report["n_matched"] == n
    assert report["centre_error_relative"]["max"] < 1e-9 and report["rotation_error_deg"]["max"] < 1e-5


def test_numeric_ids_match_whatever_their_padding(tmp_path: Path, truth_poses: list[np.ndarray]) -> None:
    """A reference naming its images 0001.jpg (instant-ngp) is the capture the frames stage calls frame_00001."""
    pred = write_named(tmp_path / "pred.json", [moved(p) for p in truth_poses], frames_stage_names(range(1, 11)))
    truth = write_named(tmp_path / "truth.json", truth_poses, [f"./images/{i:04d}.jpg" for i in range(1, 11)])
    report = compare_poses(pred, truth)
    assert report["matched_by"] == "frame id"
    assert_exact(report, 10)
    bare = write_named(tmp_path / "bare.json", truth_poses, [f"{i:05d}" for i in range(1, 11)])
    assert_exact(compare_poses(pred, bare), 10)
    # a shifted numbering pairs the wrong frames: the errors must show it
    shifted = write_named(tmp_path / "shifted.json", truth_poses, [f"{i:04d}.jpg" for i in range(2, 12)])
    assert compare_poses(pred, shifted)["centre_error_relative"]["max"] > 1e-3


def test_image_stems_match_when_frame_ids_collide(tmp_path: Path, truth_poses: list[np.ndarray]) -> None:
    """Two cameras both numbered 0001..0005: frame ids are ambiguous, the stems are not."""
    stems = [f"{cam}_{i:04d}" for cam in ("left", "right") for i in range(1, 6)]
    pred = write_named(tmp_path / "pred.json", [moved(p) for p in truth_poses], [f"images/{s}.png" for s in stems])
    order = [9, 3, 0, 5, 7, 1, 8, 2, 6, 4]  # the reference lists them in another order
    truth = write_named(tmp_path / "truth.json", [truth_poses[k] for k in order],
                        [f"{stems[k].upper()}.JPG" for k in order])
    report = compare_poses(pred, truth)
    assert report["matched_by"] == "image stem" and report["match_counts"]["frame id"] == 0
    assert_exact(report, 10)


def test_colmap_image_names(tmp_path: Path, truth_poses: list[np.ndarray]) -> None:
    """A COLMAP model as reference: its image names (with a camera subfolder) pair with the file paths."""
    names = [f"{cam}/{i:04d}.jpg" for cam in ("cam0", "cam1") for i in range(5)]
    truth = write_colmap_model(tmp_path / "sparse" / "0", truth_poses, names)
    pred = write_named(tmp_path / "pred.json", [moved(p) for p in truth_poses],
                       [f"images/{n.replace('.jpg', '.png')}" for n in names])
    report = compare_poses(pred, truth)
    assert report["matched_by"] == "image path"
    assert_exact(report, 10)
    # and a COLMAP model as prediction, against IMG_0001.JPG-style names
    colmap_pred = write_colmap_model(tmp_path / "pred_model", [moved(p) for p in truth_poses],
                                     [f"IMG_{i:04d}.JPG" for i in range(10)])
    truth_json = write_named(tmp_path / "truth.json", truth_poses, frames_stage_names(range(10)))
    assert_exact(compare_poses(colmap_pred, truth_json), 10)


def test_reference_without_file_paths(tmp_path: Path, truth_poses: list[np.ndarray],
                                      capsys: pytest.CaptureFixture[str]) -> None:
    """Frames that carry only colmap_im_id: refused by name with a pointer to --match order, which pairs them."""
    pred = write_named(tmp_path / "pred.json", [moved(p) for p in truth_poses], frames_stage_names(range(3, 13)))
    truth = write_named(tmp_path / "truth.json", truth_poses, [None] * 10)
    args = ["compare", "--pred", str(pred), "--truth", str(truth)]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "the reference's frames carry no file_path" in err and "pass --match order" in err
    assert "frame_00003, frame_00004" in err and "#0 (no file_path)" in err
    assert main([*args, "--match", "order", "--out", str(tmp_path / "err.json")]) == 0
    report = json.loads((tmp_path / "err.json").read_text())
    assert report["matched_by"] == "order"
    assert_exact(report, 10)
    # pred listed in another order: order matching sorts named frames by their number first
    shuffled = write_named(tmp_path / "shuffled.json", [moved(truth_poses[k]) for k in (9, 0, 5, 1, 2, 3, 4, 6, 7, 8)],
                           frames_stage_names([12, 3, 8, 4, 5, 6, 7, 9, 10, 11]))
    assert_exact(compare_poses(shuffled, truth, match="order"), 10)


def test_error_lists_the_ids_of_both_sides(tmp_path: Path, truth_poses: list[np.ndarray],
                                          capsys: pytest.CaptureFixture[str]) -> None:
    pred = write_named(tmp_path / "pred.json", truth_poses, frames_stage_names(range(10)))
    truth = write_named(tmp_path / "truth.json", truth_poses[:9], [f"room_b{i}.jpg" for i in range(9)])
    args = ["compare", "--pred", str(pred), "--truth", str(truth)]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "frames seen in the prediction: frame_00000, frame_00001, frame_00002, frame_00003, frame_00004, ... " \
           "(10 frames)" in err
    assert "in the reference: room_b0, room_b1, room_b2, room_b3, room_b4, ... (9 frames)" in err
    # different counts: --match order cannot help, so it is not suggested as the fix
    assert "fix: compare poses of the same capture" in err and "pass --match order" not in err
    assert main([*args, "--match", "order"]) == 2
    err = capsys.readouterr().err
    assert "the prediction has 10 frames and the reference" in err and "pass --match order" not in err
