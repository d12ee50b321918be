"""`livescene poses import`: a COLMAP model made elsewhere becomes the POSES folder of `livescene poses`.

The model is written with pycolmap from known poses under another naming scheme (0001.jpg, as a camera or
ns-process-data names images), binary and text, at the frames' size and at twice it; the frames come from
the frames stage run on the image folder the model was "made" from.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import cv2
import numpy as np
import open3d as o3d
import pycolmap
import pytest
from colmap_testdata import OPENCV_K, RADIAL_K, default_scene, synthetic_model, write_model
from nerfstudio_mirror import read_like_nerfstudio
from poses_testdata import SMALL_CAMERA

from stages.frames import FramesConfig, extract_frames
from stages.poses.cli import main as poses_main
from stages.poses.colmap_import import ImportConfig, import_model
from stages.poses.errors import PoseQualityError, StaticCameraError
from stages.poses.model_export import transforms_dict
from stages.scene import STAGE_MARKER, InputError, look_at, project_points, read_scene

NUMBERS, POSES = default_scene(12)
COLMAP_NAMES = [f"{i:04d}.jpg" for i in NUMBERS]


@pytest.fixture(scope="module")
def capture(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """(image folder as a camera writes it: 0001.jpg ..., FRAMES folder of `livescene frames` on it)."""
    root = tmp_path_factory.mktemp("capture")
    source = root / "photos"
    source.mkdir()
    rng = np.random.default_rng(0)
    for name in COLMAP_NAMES:
        noise = rng.integers(0, 255, (SMALL_CAMERA.height, SMALL_CAMERA.width, 3), np.uint8)
        cv2.imwrite(str(source / name), cv2.GaussianBlur(noise, (3, 3), 0))
    frames = root / "frames"
    extract_frames(FramesConfig(source=source, out_dir=frames, progress=False))
    return source, frames


def _model(tmp_path: Path, layout: str = "sparse/0", binary: bool = True, scale: int = 1,
           names: list[str] | None = None, poses: list[np.ndarray] | None = None, model: str = "RADIAL") -> Path:
    """A COLMAP project folder holding the model at ``layout``; returns the project folder."""
    camera = SMALL_CAMERA.scaled(scale) if scale != 1 else SMALL_CAMERA
    rec = synthetic_model(names or COLMAP_NAMES, poses or POSES, camera, model=model)
    project = tmp_path / "colmap_project"
    write_model(rec, project / layout if layout != "." else project, binary=binary)
    return project


@pytest.mark.parametrize(("binary", "layout"), [(True, "sparse/0"), (False, "."), (True, "colmap/sparse/0")])
def test_import_matches_frames_by_number(capture: tuple[Path, Path], tmp_path: Path, binary: bool,
                                         layout: str) -> None:
    _source, frames = capture
    project = _model(tmp_path, layout, binary)
    out = frames.parent / f"poses_{binary}_{layout.replace('/', '_')}"  # beside FRAMES, as results/<scene>/poses
    code = poses_main(["import", "--model", str(project), "--frames", str(frames), "--out", str(out)])
    assert code == 0
    assert {p.name for p in out.iterdir()} == {"sparse", "transforms.json", "points3D.ply", "scene.json", "poses.json",
                                               STAGE_MARKER}
    transforms = json.loads((out / "transforms.json").read_text())
    frame_names = [f"frame_{i:05d}.png" for i in NUMBERS]
    # paths resolve from the folder of transforms.json (nerfstudio's data_dir / file_path)
    assert [f["file_path"] for f in transforms["frames"]] == [f"../frames/images/{n}" for n in frame_names]
    assert all((out / f["file_path"]).is_file() for f in transforms["frames"])
    assert [f["source_index"] for f in transforms["frames"]] == NUMBERS
    summary = json.loads((out / "poses.json").read_text())
    # the model's poses, moved rigidly into the gravity- and wall-aligned world frame
    new_from_old = np.vstack([summary["world_frame"]["new_from_old"], [0.0, 0.0, 0.0, 1.0]])
    np.testing.assert_allclose(new_from_old[:3, :3] @ new_from_old[:3, :3].T, np.eye(3), atol=1e-12)
    for frame, truth in zip(transforms["frames"], POSES, strict=True):
        np.testing.assert_allclose(frame["transform_matrix"], new_from_old @ truth, atol=1e-9)
    assert transforms["fl_x"] == SMALL_CAMERA.fx and transforms["w"] == SMALL_CAMERA.width
    assert (transforms["k1"], transforms["k2"]) == RADIAL_K
    assert summary["source"] == "import"
    assert summary["up_check"]["n_points"] > 0  # the second up, as `livescene poses` checks its own models
    assert summary["imported_from"]["model"] == str((project / layout).resolve())
    assert summary["imported_from"]["format"] == ("binary" if binary else "text")
    assert summary["registered"] == frame_names and summary["unregistered"] == []
    assert summary["registered_fraction"] == 1.0 and summary["mean_reprojection_error"] < 1e-6
    assert summary["renamed"] == dict(zip(COLMAP_NAMES, frame_names, strict=True))
    # sparse/0 names the frames it is stored next to, so it is a COLMAP workspace of FRAMES/images
    rec = pycolmap.Reconstruction(out / "sparse" / "0")
    assert sorted(im.name for im in rec.images.values()) == frame_names
    cloud = o3d.io.read_point_cloud(str(out / "points3D.ply"))
    assert len(cloud.points) == summary["n_points3D"] == rec.num_points3D() > 50
    box = np.asarray(json.loads((out / "scene.json").read_text())["scene_box"])
    centres = np.array([(new_from_old @ p)[:3, 3] for p in POSES])
    assert (centres >= box[0] - 1e-9).all() and (centres <= box[1] + 1e-9).all()  # the box holds the cameras
    # the scene stage reads it (and nerfstudio would: see tests/nerfstudio_mirror.py)
    view = read_like_nerfstudio(out)
    assert view.image_filenames == [(out / "../frames/images" / n) for n in frame_names]


def test_import_output_is_read_by_the_scene_reader(capture: tuple[Path, Path], tmp_path: Path) -> None:
    _source, frames = capture
    out = tmp_path / "poses"
    import_model(ImportConfig(model_dir=_model(tmp_path), out_dir=out, frames_dir=frames))
    ds = read_scene(out, validate=True, deep=True)  # every image found through ../frames/images
    assert [f.frame_id for f in ds.frames] == [f"{i:05d}" for i in NUMBERS]
    assert ds.camera.distortion == {"k1": RADIAL_K[0], "k2": RADIAL_K[1]}


def test_import_with_the_image_folder(capture: tuple[Path, Path], tmp_path: Path) -> None:
    source, _frames = capture
    out = tmp_path / "poses"
    # orient=False (--no-orient): the model's own world frame, pose for pose
    summary = import_model(ImportConfig(model_dir=_model(tmp_path, binary=False), out_dir=out, images_dir=source,
                                        orient=False))
    assert summary["world_frame"] is None and "up_check" not in summary  # a world kept as given is not checked
    transforms = json.loads((out / "transforms.json").read_text())
    assert [f["file_path"] for f in transforms["frames"]] == [os.path.relpath(source / n, out) for n in COLMAP_NAMES]
    assert all((out / f["file_path"]).is_file() for f in transforms["frames"])
    assert summary["renamed"] == {} and summary["n_registered"] == len(NUMBERS)
    for frame, truth in zip(transforms["frames"], POSES, strict=True):
        np.testing.assert_allclose(frame["transform_matrix"], truth, atol=1e-9)


def test_macos_metadata_copies_in_the_image_folder_are_no_frames(capture: tuple[Path, Path], tmp_path: Path) -> None:
    # macOS writes ``._NAME`` (AppleDouble metadata, not an image) beside each photo it copies to a foreign disk
    source = tmp_path / "photos"
    shutil.copytree(capture[0], source)
    for name in COLMAP_NAMES:
        (source / f"._{name}").write_bytes(b"\x00\x05\x16\x07" + bytes(4000))
    summary = import_model(ImportConfig(model_dir=_model(tmp_path), out_dir=tmp_path / "poses", images_dir=source,
                                        orient=False))
    assert summary["n_registered"] == len(NUMBERS) and summary["unregistered"] == []


def test_model_made_at_full_resolution_is_rescaled(capture: tuple[Path, Path], tmp_path: Path) -> None:
    """A model of the full-size photos imported for frames at half their size: intrinsics and keypoints follow."""
    _source, frames = capture
    out = tmp_path / "poses"
    summary = import_model(ImportConfig(model_dir=_model(tmp_path, scale=2), out_dir=out, frames_dir=frames))
    transforms = json.loads((out / "transforms.json").read_text())
    assert (transforms["w"], transforms["h"]) == (SMALL_CAMERA.width, SMALL_CAMERA.height)
    assert transforms["fl_x"] == pytest.approx(SMALL_CAMERA.fx) and transforms["cx"] == pytest.approx(SMALL_CAMERA.cx)
    assert summary["intrinsics_scale"] == {"1": [0.5, 0.5]}
    rec = pycolmap.Reconstruction(out / "sparse" / "0")
    rec.update_point_3d_errors()  # recomputed from the rescaled camera and keypoints: still exact
    assert rec.compute_mean_reprojection_error() < 1e-6


def test_an_opencv_model_at_full_resolution_keeps_its_distortion_through_the_import(capture: tuple[Path, Path],
                                                                                    tmp_path: Path) -> None:
    """COLMAP OPENCV (fx, fy, cx, cy, k1, k2, p1, p2) of the photos at twice the frames' size -> transforms.json
    (camera_model OPENCV, focal and centre halved, the coefficients as they were: they act on normalised
    coordinates) -> the dataset Camera, which projects every 3D point of sparse/0 onto its (rescaled) keypoint."""
    _source, frames = capture
    out = tmp_path / "poses"
    import_model(ImportConfig(model_dir=_model(tmp_path, scale=2, model="OPENCV"), out_dir=out, frames_dir=frames))
    transforms = json.loads((out / "transforms.json").read_text())
    assert transforms["camera_model"] == "OPENCV"
    assert (transforms["k1"], transforms["k2"], transforms["p1"], transforms["p2"]) == OPENCV_K
    assert transforms["fl_x"] == pytest.approx(SMALL_CAMERA.fx) and transforms["cy"] == pytest.approx(SMALL_CAMERA.cy)
    ds = read_scene(out, validate=True)
    assert ds.camera.distortion == dict(zip(("k1", "k2", "p1", "p2"), OPENCV_K, strict=True))
    rec = pycolmap.Reconstruction(out / "sparse" / "0")  # written in the world of transforms.json
    pose_of = {Path(f.file_path).name: f.c2w for f in ds.frames}
    misses = []
    for image in rec.images.values():
        seen = [p for p in image.points2D if p.has_point3D()]
        xyz = np.array([rec.points3D[p.point3D_id].xyz for p in seen])
        uv, _ = project_points(ds.camera, pose_of[image.name], xyz)
        misses.append(np.abs(uv - np.array([p.xy for p in seen])).max())
    assert max(misses) < 1e-6


def test_other_aspect_ratio_is_refused(capture: tuple[Path, Path], tmp_path: Path) -> None:
    _source, frames = capture
    turned = SMALL_CAMERA.__class__(fx=100.0, fy=100.0, cx=60.0, cy=80.0, width=120, height=160)
    rec = synthetic_model(COLMAP_NAMES, POSES, turned)
    model = write_model(rec, tmp_path / "model")
    with pytest.raises(InputError, match=r"120x160 but its images.*are 160x120.*turned by 90 degrees.*fix:"):
        import_model(ImportConfig(model_dir=model, out_dir=tmp_path / "poses", frames_dir=frames))
    assert not (tmp_path / "poses").exists()


def test_too_few_frames_in_the_model_names_both_sides(capture: tuple[Path, Path], tmp_path: Path) -> None:
    _source, frames = capture
    project = _model(tmp_path, names=COLMAP_NAMES[:5], poses=POSES[:5])
    with pytest.raises(PoseQualityError) as info:
        import_model(ImportConfig(model_dir=project, out_dir=tmp_path / "poses", frames_dir=frames))
    message = str(info.value)
    assert "only 5 of 12 frames (42%)" in message
    assert "frame_00006..frame_00012 (7)" in message  # frames without a posed image
    assert "0001..0005 (5)" in message  # what the model holds
    assert "fix:" in message and "--min-registered" in message
    summary = import_model(ImportConfig(model_dir=project, out_dir=tmp_path / "poses", frames_dir=frames,
                                        min_registered=0.4))
    assert summary["n_registered"] == 5 and summary["unregistered"][0] == "frame_00006.png"


def test_model_images_without_a_frame_are_left_out(capture: tuple[Path, Path], tmp_path: Path) -> None:
    """The frames stage kept every other image (--stride 2): the model's other images have no frame."""
    source, _frames = capture
    frames = tmp_path / "frames_stride2"
    extract_frames(FramesConfig(source=source, out_dir=frames, stride=2, progress=False))
    kept = sorted(p.name for p in (frames / "images").iterdir())
    summary = import_model(ImportConfig(model_dir=_model(tmp_path), out_dir=tmp_path / "poses", frames_dir=frames))
    assert summary["registered"] == kept and summary["registered_fraction"] == 1.0
    assert len(summary["model_images_without_frame"]) == len(NUMBERS) - len(kept)
    assert any("match no frame" in w for w in summary["warnings"])


def test_bad_models_are_refused_with_a_fix(capture: tuple[Path, Path], tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    _source, frames = capture
    out = tmp_path / "poses"

    def refused(model: Path, *fragments: str) -> None:
        code = poses_main(["import", "--model", str(model), "--frames", str(frames), "--out", str(out)])
        err = capsys.readouterr().err
        assert code == 2 and err.startswith("error: ") and "fix:" in err, err
        for fragment in fragments:
            assert fragment in err, err
        assert not out.exists()

    refused(tmp_path / "nowhere", "nowhere: COLMAP model folder not found")
    empty = tmp_path / "empty"
    empty.mkdir()
    refused(empty, "no COLMAP model here")
    project = _model(tmp_path)
    sparse = project / "sparse" / "0"
    (sparse / "points3D.bin").unlink()
    refused(project, "points3D.bin: the COLMAP model is incomplete", "points3D.bin missing")
    write_model(synthetic_model(COLMAP_NAMES, POSES), sparse)
    data = (sparse / "images.bin").read_bytes()
    (sparse / "images.bin").write_bytes(data[: len(data) - 9])  # cut inside the last image's keypoints
    refused(project, "images.bin: ", "cut short or corrupt (it ends inside record 12 of the 12")
    write_model(synthetic_model(COLMAP_NAMES, POSES), sparse)
    cameras = (sparse / "cameras.bin").read_bytes()
    (sparse / "cameras.bin").write_bytes(cameras[:-8])  # COLMAP itself reads this without a word
    refused(project, "cameras.bin: ", "cut short or corrupt")
    text = write_model(synthetic_model(COLMAP_NAMES, POSES), tmp_path / "text", binary=False)
    lines = (text / "images.txt").read_text().splitlines(keepends=True)
    (text / "images.txt").write_text("".join(lines[:-4]))  # two images short of the header's count
    refused(text, "images.txt: the header says 12 images but the file holds 10")
    write_model(synthetic_model(COLMAP_NAMES, POSES), text, binary=False)
    (text / "cameras.txt").write_text("1 PINHOLE one hundred\n")
    refused(text, "pycolmap cannot read this text COLMAP model")
    fisheye = write_model(synthetic_model(COLMAP_NAMES, POSES, model="OPENCV_FISHEYE"), tmp_path / "fisheye")
    refused(fisheye, "OPENCV_FISHEYE model", "image_undistorter")


def test_names_without_numbers_and_output_over_the_model(capture: tuple[Path, Path], tmp_path: Path) -> None:
    _source, frames = capture
    project = _model(tmp_path, names=[f"view{c}.jpg" for c in "abcdefghijkl"])
    with pytest.raises(InputError, match=r"carry no frame number.*'viewa.jpg'.*fix: pass --images"):
        import_model(ImportConfig(model_dir=project, out_dir=tmp_path / "poses", frames_dir=frames))
    with pytest.raises(InputError, match=r"the output folder holds the model"):
        import_model(ImportConfig(model_dir=project / "sparse" / "0", out_dir=project, frames_dir=frames))
    assert (project / "sparse" / "0" / "cameras.bin").is_file()


def test_cli_help_names_the_interface(capsys: pytest.CaptureFixture[str]) -> None:
    """The workflow calls `livescene poses import --model M --frames F --out O` (workflow/rules/poses.smk)."""
    with pytest.raises(SystemExit):
        poses_main(["import", "--help"])
    text = capsys.readouterr().out
    for flag in ("--model", "--frames", "--images", "--out", "--min-registered"):
        assert flag in text


def test_nerfstudio_dataparser_reads_the_import(capture: tuple[Path, Path], tmp_path: Path) -> None:
    """nerfstudio's own parser on POSES (`ns-train --data POSES`), where it can be imported (not a dependency)."""
    parsers = pytest.importorskip("nerfstudio.data.dataparsers.nerfstudio_dataparser")
    _source, frames = capture
    out = frames.parent / "poses_for_nerfstudio"
    import_model(ImportConfig(model_dir=_model(tmp_path), out_dir=out, frames_dir=frames))
    parser = parsers.NerfstudioDataParserConfig(data=out, load_3D_points=True).setup()
    outputs = parser.get_dataparser_outputs(split="train")
    assert outputs.image_filenames and all(Path(p).is_file() for p in outputs.image_filenames)
    assert float(outputs.cameras.fx[0]) == pytest.approx(SMALL_CAMERA.fx)
    assert outputs.cameras.distortion_params[0, :2].tolist() == pytest.approx(list(RADIAL_K))
    assert len(outputs.metadata["points3D_xyz"]) == json.loads((out / "poses.json").read_text())["n_points3D"]


def test_transforms_dict_names_images_relative_to_the_output(capture: tuple[Path, Path]) -> None:
    """What `livescene poses` writes when given its frames' folder (stages/poses/model_export.py)."""
    _source, frames = capture
    names = [f"frame_{i:05d}.png" for i in NUMBERS]
    rec = synthetic_model(names, POSES)
    out = frames.parent / "poses"
    transforms = transforms_dict(rec, dict(zip(names, NUMBERS, strict=True)), image_dir=frames / "images",
                                 out_dir=out)
    assert [f["file_path"] for f in transforms["frames"]] == [f"../frames/images/{n}" for n in names]
    assert transforms_dict(rec, {})["frames"][0]["file_path"] == "images/frame_00001.png"  # without: as before


def test_a_model_with_two_cameras_gives_per_frame_intrinsics(capture: tuple[Path, Path], tmp_path: Path) -> None:
    _source, frames = capture
    zoomed = SMALL_CAMERA.__class__(fx=120.0, fy=120.0, cx=80.0, cy=60.0, width=160, height=120)
    rec = synthetic_model(COLMAP_NAMES, POSES, second_camera=zoomed)
    out = frames.parent / "poses_two_cameras"
    import_model(ImportConfig(model_dir=write_model(rec, tmp_path / "model"), out_dir=out, frames_dir=frames))
    transforms = json.loads((out / "transforms.json").read_text())
    assert "fl_x" not in transforms and transforms["camera_model"] == "OPENCV"
    assert [f["fl_x"] for f in transforms["frames"][:2]] == [SMALL_CAMERA.fx, zoomed.fx]
    ds = read_scene(out, deep=True)
    assert [ds.camera_of(f).fx for f in ds.frames[:2]] == [SMALL_CAMERA.fx, zoomed.fx]
    assert read_like_nerfstudio(out).intrinsics[1]["fl_x"] == zoomed.fx


def test_renamed_frames_of_a_video_are_flagged(capture: tuple[Path, Path], tmp_path: Path) -> None:
    """Video frames are numbered by decode position: pairing another tool's frame numbers with them is a guess."""
    _source, frames = capture
    video_frames = tmp_path / "frames"
    shutil.copytree(frames, video_frames)
    meta = json.loads((video_frames / "frames.json").read_text())
    (video_frames / "frames.json").write_text(json.dumps({**meta, "source_kind": "video"}))
    summary = import_model(ImportConfig(model_dir=_model(tmp_path), out_dir=tmp_path / "poses",
                                        frames_dir=video_frames))
    assert any("the frames come from a video" in w for w in summary["warnings"])


def test_the_camera_path_gate_of_poses_applies_to_a_model(capture: tuple[Path, Path], tmp_path: Path) -> None:
    """A model made elsewhere passes the trajectory gate of `livescene poses`: a tripod clip is refused, a camera
    thrown across the room is dropped with a warning."""
    _source, frames = capture
    eye = POSES[0][:3, 3]
    tripod = [look_at(eye + np.random.default_rng(k).normal(0.0, 1e-4, 3), p[:3, 3] + 2.0 * (p[:3, 3] - eye)
                      - 2.0 * p[:3, 2]) for k, p in enumerate(POSES)]
    with pytest.raises(StaticCameraError, match="the camera does not move") as info:
        import_model(ImportConfig(model_dir=_model(tmp_path / "a", poses=tripod), out_dir=tmp_path / "p1",
                                  frames_dir=frames))
    assert str(frames) in str(info.value)
    assert not (tmp_path / "p1").exists()

    thrown = [p.copy() for p in POSES]
    thrown[6][:3, 3] += [0.0, 0.0, 40.0]  # frame 7 lands far above the room
    summary = import_model(ImportConfig(model_dir=_model(tmp_path / "b", poses=thrown), out_dir=tmp_path / "p2",
                                        frames_dir=frames))
    assert summary["trimmed"] == ["frame_00007.png"] and summary["trajectory"]["verdict"] == "trim"
    assert "frame_00007.png" not in summary["registered"] and summary["n_registered"] == 11
    assert any("jump away from their neighbours" in w for w in summary["warnings"])
    ds = json.loads((tmp_path / "p2" / "transforms.json").read_text())
    assert len(ds["frames"]) == 11 and not any("frame_00007" in f["file_path"] for f in ds["frames"])
    assert len(pycolmap.Reconstruction(tmp_path / "p2" / "sparse" / "0").reg_image_ids()) == 11
