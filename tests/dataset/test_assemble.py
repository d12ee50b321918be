"""`livescene dataset assemble`: frames + poses + labels + states -> one validated scene dataset, and back."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from stages.cli import main as livescene_main
from stages.dataset import AssembleConfig, assemble_scene
from stages.dataset.cli import main as dataset_main
from stages.labels import LabelsConfig, ingest_labels
from stages.scene import Camera, SceneError, look_at, read_scene
from stages.scene.cli import main as scene_main
from stages.scene.transforms import camera_to_dict
from stages.states import StatesConfig, compute_states

H, W = 12, 16
N = 6
NAMES = ["door", "drawer"]


def make_stage_outputs(root: Path, registered: list[int] | None = None) -> dict[str, Path]:
    """FRAMES (6 frames, source indices 0, 3, 6, ...), POSES (some registered), LABELS (frame 4 unlabelled), STATES."""
    registered = list(range(N)) if registered is None else registered
    rng = np.random.default_rng(0)
    frames = root / "frames"
    (frames / "images").mkdir(parents=True)
    (root / "masks_png").mkdir()
    rows = ["frame,source_index,timestamp,sharpness"]
    for i in range(N):
        name = f"frame_{3 * i:05d}.png"
        cv2.imwrite(str(frames / "images" / name), rng.integers(0, 255, (H, W, 3), dtype=np.uint8))
        rows.append(f"{name},{3 * i},{0.3 * i:.1f},1.0")
        if i != 4:  # frame 4 carries no mask
            lab = np.zeros((H, W), np.uint8)
            lab[2:6, 1 + i:5 + i] = 1
            lab[8:11, 8:14] = 2
            cv2.imwrite(str(root / "masks_png" / name), lab)
    (frames / "frames.csv").write_text("\n".join(rows) + "\n")
    (root / "masks_png" / "mapping.yaml").write_text("1: door\n2: drawer\n")

    poses = root / "poses"
    poses.mkdir()
    camera = Camera(fx=20.0, fy=20.0, cx=W / 2, cy=H / 2, width=W, height=H)
    entries = []
    for i in registered:
        c2w = look_at(np.array([3 * np.cos(i), 3 * np.sin(i), 1.0]), np.zeros(3))
        entries.append({"file_path": f"images/frame_{3 * i:05d}.png", "transform_matrix": c2w.tolist(),
                        "source_index": 3 * i, "state": {"door": 0.123}})
    (poses / "transforms.json").write_text(json.dumps({**camera_to_dict(camera), "frames": entries}))
    (poses / "scene.json").write_text(json.dumps({"scene_box": [[-1, -1, -1], [1, 1, 1]], "units": "colmap"}))

    labels = root / "labels"
    # frame 00012 has no mask and stays without one (not propagated): what assemble does with such frames
    ingest_labels(LabelsConfig(input=root / "masks_png", frames=frames, out=labels, progress=False,
                               missing_masks="leave"))
    keys = root / "key_frame_value.yaml"
    keys.write_text(yaml.safe_dump({"frame_00000": {"door": 0.0, "drawer": 1.0}, "frame_00009": {"door": 1.0},
                                    "frame_00015": {"drawer": 0.0, "door": 0.5}}))
    states = root / "states"
    compute_states(StatesConfig(key_frames=keys, frames=frames / "frames.csv", out=states, method="linear"))
    prompts = root / "prompts.yaml"
    prompts.write_text(yaml.safe_dump({"door": {"synonyms": ["cabinet door"], "description": "a door"}}))
    return {"frames": frames, "poses": poses, "labels": labels, "states": states, "prompts": prompts}


def test_round_trip(tmp_path):
    paths = make_stage_outputs(tmp_path, registered=[0, 1, 2, 4, 5])  # frame 3 (source 9) not registered
    out = tmp_path / "ds"
    code = dataset_main(["assemble", "--frames", str(paths["frames"]), "--poses", str(paths["poses"]),
                         "--labels", str(paths["labels"]), "--states", str(paths["states"]),
                         "--prompts", str(paths["prompts"]), "--out", str(out), "--no-progress"])
    assert code == 0
    ds = read_scene(out, deep=True)
    assert ds.objects == NAMES and ds.object_ids == [1, 2]
    assert [f.file_path for f in ds.frames] == [f"images/frame_{3 * i:05d}.png" for i in (0, 1, 2, 4, 5)]
    assert [f.source_index for f in ds.frames] == [0, 3, 6, 12, 15]
    assert [f.split for f in ds.frames] == ["test", "train", "test", "train", "test"]
    assert ds.meta["unregistered_frames"] == ["frame_00009.png"]
    assert ds.meta["frames_without_masks"] == ["00012"]
    np.testing.assert_array_equal(ds.scene_box, [[-1, -1, -1], [1, 1, 1]])
    assert ds.prompts["door"]["synonyms"] == ["cabinet door"]
    # key frame 00009 belongs to an unregistered frame and is dropped; the others stay
    assert ds.key_frames == {"00000": {"door": 0.0, "drawer": 1.0}, "00015": {"drawer": 0.0, "door": 0.5}}
    poses = json.loads((paths["poses"] / "transforms.json").read_text())["frames"]
    by_name = {Path(p["file_path"]).name: np.array(p["transform_matrix"]) for p in poses}
    for f in ds.frames:
        np.testing.assert_array_equal(f.c2w, by_name[Path(f.file_path).name])
        src = cv2.imread(str(paths["frames"] / "images" / Path(f.file_path).name))
        np.testing.assert_array_equal(cv2.imread(str(ds.image_path(f))), src)
        if f.frame_id != "00012":
            np.testing.assert_array_equal(ds.load_mask(f), np.load(paths["labels"] / "masks" / f"{f.frame_id}.npy"))
    # states: linear door 0 @0 -> 1 @9 -> 0.5 @15; truth states in transforms.json are ignored
    door = ds.state_matrix()[:, 0]
    np.testing.assert_allclose(door, [0.0, 1 / 3, 2 / 3, 1 - 0.5 * 3 / 6, 0.5])
    assert scene_main(["validate", str(out)]) == 0  # the existing subcommands still work


@pytest.mark.parametrize("copy", [False, True])
def test_images_and_masks_are_linked_not_copied_unless_asked(tmp_path, copy):
    paths = make_stage_outputs(tmp_path)
    out = tmp_path / "ds"
    assemble_scene(AssembleConfig(frames=paths["frames"], poses=paths["poses"], labels=paths["labels"],
                                  states=paths["states"], out=out, copy_images=copy, progress=False))
    image, mask = out / "images" / "frame_00003.png", out / "masks" / "00003.npy"
    assert image.samefile(paths["frames"] / "images" / "frame_00003.png") is not copy
    assert mask.samefile(paths["labels"] / "masks" / "00003.npy") is not copy
    np.testing.assert_array_equal(np.load(mask), np.load(paths["labels"] / "masks" / "00003.npy"))


def test_truth_transforms_file_as_poses(tmp_path):
    paths = make_stage_outputs(tmp_path)
    ds = assemble_scene(AssembleConfig(frames=paths["frames"], poses=paths["poses"] / "transforms.json",
                                       states=paths["states"], out=tmp_path / "ds", split="every_n", split_n=3,
                                       progress=False))
    assert len(ds.frames) == N and not ds.has_masks and ds.objects == NAMES
    assert [f.split for f in ds.frames] == ["train", "test", "train", "train", "test", "train"]
    assert ds.scene_box is not None


def test_states_for_other_objects_than_the_labels(tmp_path):
    paths = make_stage_outputs(tmp_path)
    (paths["labels"] / "mapping.yaml").write_text("1: door\n2: fridge\n")
    with pytest.raises(SceneError, match=r"states\.csv: states are for objects \['door', 'drawer'\] but .*names "
                                         r"\['door', 'fridge'\]"):
        assemble_scene(AssembleConfig(frames=paths["frames"], poses=paths["poses"], labels=paths["labels"],
                                      states=paths["states"], out=tmp_path / "ds", progress=False))
    assert not (tmp_path / "ds").exists()


def test_poses_of_other_frames_are_refused(tmp_path, capsys):
    paths = make_stage_outputs(tmp_path)
    data = json.loads((paths["poses"] / "transforms.json").read_text())
    for fr in data["frames"]:
        fr["file_path"] = fr["file_path"].replace("frame_", "other_9")
    (paths["poses"] / "transforms.json").write_text(json.dumps(data))
    code = dataset_main(["assemble", "--frames", str(paths["frames"]), "--poses", str(paths["poses"]),
                         "--out", str(tmp_path / "ds")])
    err = capsys.readouterr().err
    assert code == 2 and "transforms.json: no pose matches an image of" in err


def test_image_size_that_is_no_integer_factor_of_the_poses(tmp_path):
    paths = make_stage_outputs(tmp_path)
    data = json.loads((paths["poses"] / "transforms.json").read_text())
    data["w"], data["h"] = 24, 18
    (paths["poses"] / "transforms.json").write_text(json.dumps(data))
    with pytest.raises(SceneError, match=r"poses are for 24x18 images but the frames are 16x12"):
        assemble_scene(AssembleConfig(frames=paths["frames"], poses=paths["poses"], out=tmp_path / "ds",
                                      progress=False))


def test_old_scene_assemble_name_runs_the_dataset_stage(tmp_path, capsys):
    """`livescene scene assemble` stays an alias (docs/data-contract.md, "Scene dataset"); the scene CLI itself,
    which may not import the dataset stage, points to the new command."""
    paths = make_stage_outputs(tmp_path)
    out = tmp_path / "ds"
    code = livescene_main(["scene", "assemble", "--frames", str(paths["frames"]), "--poses", str(paths["poses"]),
                           "--states", str(paths["states"]), "--out", str(out), "--no-progress"])
    assert code == 0 and "scene dataset, 6 frames" in capsys.readouterr().out
    assert read_scene(out).objects == NAMES
    assert scene_main(["assemble", "--frames", str(paths["frames"])]) == 2
    assert "run `livescene dataset assemble`" in capsys.readouterr().err


def test_the_poses_point_cloud_travels_with_the_dataset(tmp_path):
    paths = make_stage_outputs(tmp_path)
    ply = ("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
           "end_header\n0 0 0\n")
    (paths["poses"] / "points3D.ply").write_text(ply)
    data = json.loads((paths["poses"] / "transforms.json").read_text())
    (paths["poses"] / "transforms.json").write_text(json.dumps({**data, "ply_file_path": "points3D.ply"}))
    ds = assemble_scene(AssembleConfig(frames=paths["frames"], poses=paths["poses"], out=tmp_path / "ds",
                                       progress=False))
    assert ds.nerfstudio["ply_file_path"] == "points3D.ply"
    assert (tmp_path / "ds" / "points3D.ply").read_text() == ply
    (paths["poses"] / "points3D.ply").unlink()
    with pytest.raises(SceneError, match=r"ply_file_path 'points3D\.ply' names no file"):
        assemble_scene(AssembleConfig(frames=paths["frames"], poses=paths["poses"], out=tmp_path / "ds2",
                                      progress=False))
    assert not (tmp_path / "ds2").exists()


def test_an_image_given_two_poses_is_refused(tmp_path, capsys):
    paths = make_stage_outputs(tmp_path)
    data = json.loads((paths["poses"] / "transforms.json").read_text())
    twin = dict(data["frames"][2], file_path=data["frames"][0]["file_path"])
    data["frames"].append(twin)
    (paths["poses"] / "transforms.json").write_text(json.dumps(data))
    code = dataset_main(["assemble", "--frames", str(paths["frames"]), "--poses", str(paths["poses"]),
                         "--out", str(tmp_path / "ds")])
    err = capsys.readouterr().err
    n = len(data["frames"]) - 1
    assert code == 2 and f"frames[0] and frames[{n}] both give a pose for frame_00000.png" in err
    assert not (tmp_path / "ds").exists()


def test_an_out_folder_of_other_files_is_kept(tmp_path, capsys):
    paths = make_stage_outputs(tmp_path)
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("keep me")
    code = dataset_main(["assemble", "--frames", str(paths["frames"]), "--poses", str(paths["poses"]),
                         "--out", str(out)])
    assert code == 2 and "not an output of this stage" in capsys.readouterr().err
    assert [p.name for p in out.iterdir()] == ["notes.txt"]
    code = dataset_main(["assemble", "--frames", str(paths["frames"]), "--poses", str(paths["poses"]),
                         "--out", str(paths["frames"])])
    assert code == 2 and "is the input" in capsys.readouterr().err


def test_a_labels_folder_without_any_ingested_mask_is_refused(tmp_path, capsys):
    paths = make_stage_outputs(tmp_path)
    annotations = tmp_path / "annotations"  # what a user has before `livescene labels`: a name table, PNG masks
    (annotations / "masks").mkdir(parents=True)
    (annotations / "mapping.yaml").write_text((paths["labels"] / "mapping.yaml").read_text())
    (annotations / "masks" / "frame_00000.png").write_bytes(b"")
    code = dataset_main(["assemble", "--frames", str(paths["frames"]), "--poses", str(paths["poses"]),
                         "--labels", str(annotations), "--states", str(paths["states"]), "--out", str(tmp_path / "ds")])
    err = capsys.readouterr().err
    assert code == 2 and "none of the" in err and "frames has a mask here" in err and "livescene labels --out" in err
    assert not (tmp_path / "ds").exists()


def test_a_clamping_warning_names_the_output_not_the_temporary_folder(tmp_path):
    import pandas as pd

    paths = make_stage_outputs(tmp_path)
    table = pd.read_csv(paths["states"] / "states.csv")  # long form: frame, source_index, object, value, ...
    table.loc[1, "value"] = 1.5
    table.to_csv(paths["states"] / "states.csv", index=False)
    out = tmp_path / "ds"
    with pytest.warns(UserWarning, match="clamped") as caught:
        assemble_scene(AssembleConfig(frames=paths["frames"], poses=paths["poses"], states=paths["states"], out=out,
                                      progress=False))
    text = " ".join(str(w.message) for w in caught)
    assert str(out / "transforms.json") in text and ".ds." not in text


def test_the_cli_says_a_warning_in_one_line():
    from stages.cli import _one_line_warning

    assert _one_line_warning(UserWarning("ds/transforms.json: states clamped; fix: ..."), UserWarning, "x.py", 3,
                             "warnings.warn(...)") == "warning: ds/transforms.json: states clamped; fix: ...\n"


def test_a_truncated_mask_is_named(tmp_path, capsys):
    paths = make_stage_outputs(tmp_path)
    mask = sorted((paths["labels"] / "masks").glob("*.npy"))[0]
    mask.write_bytes(mask.read_bytes()[:90])
    code = dataset_main(["assemble", "--frames", str(paths["frames"]), "--poses", str(paths["poses"]),
                         "--labels", str(paths["labels"]), "--states", str(paths["states"]),
                         "--out", str(tmp_path / "ds")])
    err = capsys.readouterr().err
    assert code == 2 and f"{mask}: cannot read the mask" in err and "re-run `livescene labels`" in err


def _rewrite_poses(paths: dict[str, Path], edit) -> Path:
    path = paths["poses"] / "transforms.json"
    data = json.loads(path.read_text())
    edit(data)
    path.write_text(json.dumps(data))
    return path


def test_per_frame_intrinsics_with_a_shared_size_and_the_blender_form_are_read(tmp_path):
    """nerfstudio reads each intrinsic key from the top level, else from the frame; Blender's camera_angle_x takes
    the frames' size. Both give the camera of the plain form."""
    paths = make_stage_outputs(tmp_path)
    reference = assemble_scene(AssembleConfig(frames=paths["frames"], poses=paths["poses"], out=tmp_path / "ref",
                                              progress=False)).camera

    def per_frame(d: dict) -> None:
        for f in d["frames"]:
            f.update({k: d[k] for k in ("fl_x", "fl_y", "cx", "cy")})
        for k in ("fl_x", "fl_y", "cx", "cy"):
            d.pop(k)

    _rewrite_poses(paths, per_frame)
    ds = assemble_scene(AssembleConfig(frames=paths["frames"], poses=paths["poses"], out=tmp_path / "ds",
                                       progress=False))
    assert ds.camera == reference and all(f.camera in (None, reference) for f in ds.frames)

    def blender(d: dict) -> None:
        for f in d["frames"]:
            for k in ("fl_x", "fl_y", "cx", "cy"):
                f.pop(k)
        d["camera_angle_x"] = 2 * np.arctan(W / 2 / reference.fx)
        d.pop("w"), d.pop("h")

    _rewrite_poses(paths, blender)
    ds = assemble_scene(AssembleConfig(frames=paths["frames"], poses=paths["poses"], out=tmp_path / "ds2",
                                       progress=False))
    assert ds.camera.fx == pytest.approx(reference.fx) and (ds.camera.width, ds.camera.height) == (W, H)


def test_the_poses_applied_transform_is_kept(tmp_path):
    paths = make_stage_outputs(tmp_path)
    applied = [[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, -1.0, 0.0, 0.0]]  # ns-process-data's
    _rewrite_poses(paths, lambda d: d.update(applied_transform=applied))
    assemble_scene(AssembleConfig(frames=paths["frames"], poses=paths["poses"], out=tmp_path / "ds", progress=False))
    assert json.loads((tmp_path / "ds" / "transforms.json").read_text())["applied_transform"] == applied


def test_poses_for_frames_of_another_aspect_ratio_are_refused(tmp_path):
    """Poses for 32x18 images, frames of 16x12: half the width but two thirds of the height, so no resize."""
    paths = make_stage_outputs(tmp_path)
    _rewrite_poses(paths, lambda d: d.update(w=32, h=18))
    with pytest.raises(SceneError, match=r"poses are for 32x18 images but the frames are 16x12"):
        assemble_scene(AssembleConfig(frames=paths["frames"], poses=paths["poses"], out=tmp_path / "ds",
                                      progress=False))


def test_per_frame_intrinsics_for_frames_twice_the_size_are_halved(tmp_path):
    """Each frame's own camera for 32x24 images (fl 40, principal point (16, 12)) describes the 16x12 frames as
    fl 20 at (8, 6): every intrinsic halves with the image."""
    paths = make_stage_outputs(tmp_path)

    def per_frame_at_twice_the_size(d: dict) -> None:
        for k in ("fl_x", "fl_y", "cx", "cy", "w", "h"):
            d.pop(k)
        for f in d["frames"]:
            f.update({"fl_x": 40.0, "fl_y": 40.0, "cx": 16.0, "cy": 12.0, "w": 32, "h": 24})

    _rewrite_poses(paths, per_frame_at_twice_the_size)
    ds = assemble_scene(AssembleConfig(frames=paths["frames"], poses=paths["poses"], out=tmp_path / "ds",
                                       progress=False))
    expected = Camera(fx=20.0, fy=20.0, cx=8.0, cy=6.0, width=W, height=H)
    assert all(ds.camera_of(f) == expected for f in ds.frames)
