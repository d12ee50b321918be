"""Each contract violation is rejected with a message naming the file, the problem and the fix."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from stages.scene import SceneError, read_scene


def _edit_transforms(root, fn):
    path = root / "transforms.json"
    data = json.loads(path.read_text())
    fn(data)
    path.write_text(json.dumps(data))
    return path


def _expect(root, *fragments) -> SceneError:
    with pytest.raises(SceneError) as info:
        read_scene(root, deep=True)
    msg = str(info.value)
    for frag in fragments:
        assert frag in msg, msg
    assert "fix:" in msg
    return info.value


def test_missing_transforms(tmp_path):
    err = _expect(tmp_path, "transforms.json", "not found")
    assert err.path == tmp_path / "transforms.json"


def test_missing_image(tiny_dataset):
    (tiny_dataset.root / "images" / "frame_00003.png").unlink()
    _expect(tiny_dataset.root, "frame_00003.png", "not found")


def test_frame_without_mask(tiny_dataset):
    (tiny_dataset.root / "masks" / "00002.npy").unlink()
    _expect(tiny_dataset.root, "masks/00002.npy", "has no mask", "livescene labels")


def test_frame_without_mask_allowed_when_listed(tiny_dataset):
    (tiny_dataset.root / "masks" / "00002.npy").unlink()
    meta = json.loads((tiny_dataset.root / "scene.json").read_text())
    meta["frames_without_masks"] = ["00002"]
    (tiny_dataset.root / "scene.json").write_text(json.dumps(meta))
    assert len(read_scene(tiny_dataset.root).frames) == 6


def test_mask_channel_count(tiny_dataset):
    np.save(tiny_dataset.root / "masks" / "00001.npy", np.zeros((12, 16, 3), bool))
    _expect(tiny_dataset.root, "masks/00001.npy", "3 channels", "names 3 objects")


def test_mask_shape(tiny_dataset):
    np.save(tiny_dataset.root / "masks" / "00001.npy", np.zeros((6, 8, 4), bool))
    _expect(tiny_dataset.root, "masks/00001.npy", "8x6", "16x12")


def test_non_finite_pose(tiny_dataset):
    def poison(d):
        d["frames"][2]["transform_matrix"][0][3] = float("nan")

    _edit_transforms(tiny_dataset.root, poison)
    _expect(tiny_dataset.root, "transforms.json", "frames[2]", "NaN or infinite")


def test_a_state_written_as_a_word_is_named(tiny_dataset):
    def word(d):
        name = next(iter(d["frames"][1]["state"]))
        d["frames"][1]["state"][name] = "open"

    _edit_transforms(tiny_dataset.root, word)
    _expect(tiny_dataset.root, "transforms.json", "frames[1]", "is 'open', not a number")


def test_non_rigid_pose(tiny_dataset):
    def scale(d):
        m = np.array(d["frames"][1]["transform_matrix"])
        m[:3, :3] *= 2.0
        d["frames"][1]["transform_matrix"] = m.tolist()

    _edit_transforms(tiny_dataset.root, scale)
    _expect(tiny_dataset.root, "transforms.json", "frames[1]", "not orthonormal")


def test_missing_field(tiny_dataset):
    _edit_transforms(tiny_dataset.root, lambda d: d["frames"][0].pop("transform_matrix"))
    _expect(tiny_dataset.root, "transforms.json", "frames[0]", "transform_matrix")


def test_duplicate_frame_ids(tiny_dataset):
    import shutil

    shutil.copy(tiny_dataset.root / "images" / "frame_00001.png", tiny_dataset.root / "images" / "other_00001.png")

    def dup(d):
        d["frames"][2]["file_path"] = "images/other_00001.png"

    _edit_transforms(tiny_dataset.root, dup)
    _expect(tiny_dataset.root, "transforms.json", "frame id '00001'", "unique")


def test_mapping_duplicate_names(tiny_dataset):
    (tiny_dataset.root / "mapping.yaml").write_text("1: door\n2: door\n3: drawer\n")
    _expect(tiny_dataset.root, "mapping.yaml", "more than once")


def test_key_frame_for_missing_frame(tiny_dataset):
    (tiny_dataset.root / "key_frame_value.yaml").write_text("frame_00099: {object0: 1.0}\n")
    _expect(tiny_dataset.root, "key_frame_value.yaml", "'00099'", "matches no frame")


def test_key_frame_nan(tiny_dataset):
    (tiny_dataset.root / "key_frame_value.yaml").write_text("frame_00001: {object0: .nan}\n")
    _expect(tiny_dataset.root, "key_frame_value.yaml", "frame_00001", "nan")


def test_validate_cli_reports_error_and_exit_code(tiny_dataset):
    (tiny_dataset.root / "masks" / "00002.npy").unlink()
    proc = subprocess.run([sys.executable, "-m", "stages.scene", "validate", str(tiny_dataset.root)],
                          capture_output=True, text=True)
    assert proc.returncode == 2
    assert "00002.npy" in proc.stderr and "fix:" in proc.stderr


def test_validate_cli_ok(tiny_dataset):
    proc = subprocess.run([sys.executable, "-m", "stages.scene", "validate", str(tiny_dataset.root)],
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert "6 frames" in proc.stdout and "warning" not in proc.stderr


def test_validate_cli_says_which_methods_a_dataset_without_masks_serves(tiny_dataset, tmp_path):
    import shutil

    root = tmp_path / "ds"
    shutil.copytree(tiny_dataset.root, root)
    shutil.rmtree(root / "masks")
    proc = subprocess.run([sys.executable, "-m", "stages.scene", "validate", str(root)], capture_output=True,
                          text=True)
    assert proc.returncode == 0 and "valid scene dataset" in proc.stdout
    assert "has no masks/: LiveScene and CoNeRF-style refuse it" in proc.stderr and "fix: ingest masks" in proc.stderr


def test_states_outside_unit_range_are_clamped_with_a_warning_naming_the_frame(tiny_dataset):
    tpath = tiny_dataset.root / "transforms.json"
    data = json.loads(tpath.read_text())
    data["frames"][1]["state"]["object0"] = 1.3
    data["frames"][4]["state"]["object2"] = -0.2
    tpath.write_text(json.dumps(data))
    with pytest.warns(UserWarning, match="clamped") as caught:
        ds = read_scene(tiny_dataset.root)
    said = str(caught[0].message)
    assert data["frames"][1]["file_path"] in said and data["frames"][4]["file_path"] in said
    assert ds.frames[1].state["object0"] == 1.0 and ds.frames[4].state["object2"] == 0.0
    assert json.loads(tpath.read_text()) == data  # the input file is left as it was
