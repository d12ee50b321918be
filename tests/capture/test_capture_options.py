"""Options of `livescene capture` and `capture dataset` that the other tests leave at their defaults."""

from __future__ import annotations

import json
import shutil

import cv2
import numpy as np
import pytest
import yaml

from stages.capture import CaptureFolderError, capture_to_dataset, generate_capture, spec_to_dict
from stages.capture.cli import main


def test_seed_on_the_command_line_overrides_the_spec(tmp_path, small_spec):
    spec = small_spec(n_frames=2, width=32, height=24)
    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump(spec_to_dict(spec)))
    assert main(["--spec", str(path), "--out", str(tmp_path / "cap"), "--seed", "7", "--no-progress"]) == 0
    assert json.loads((tmp_path / "cap" / "capture.json").read_text())["seed"] == 7
    assert yaml.safe_load((tmp_path / "cap" / "truth" / "spec.yaml").read_text())["seed"] == 7


def test_render_scale_and_depth_preview(tiny_capture, tmp_path):
    png = tmp_path / "big.png"
    assert main(["render", "--capture", str(tiny_capture), "--pose", "2", "--scale", "2", "--out", str(png)]) == 0
    assert cv2.imread(str(png)).shape == (96, 128, 3)  # the 64x48 capture, twice the size
    depth = np.load(tmp_path / "big.depth.npy")
    preview = cv2.imread(str(tmp_path / "big.depth.png"), cv2.IMREAD_UNCHANGED)
    assert preview.shape == depth.shape
    near, far = np.unravel_index(depth.argmin(), depth.shape), np.unravel_index(depth.argmax(), depth.shape)
    assert (preview[near], preview[far]) == (255, 1)  # near is bright, the farthest hit stays apart from a miss (0)


@pytest.mark.parametrize("matrix", [np.eye(4)[:3], np.full((4, 4), np.nan)])
def test_render_refuses_a_pose_that_is_not_a_finite_4x4(tiny_capture, tmp_path, capsys, matrix):
    np.save(tmp_path / "pose.npy", matrix)
    assert (
        main(
            [
                "render",
                "--capture",
                str(tiny_capture),
                "--pose",
                str(tmp_path / "pose.npy"),
                "--out",
                str(tmp_path / "v.png"),
            ]
        )
        == 2
    )
    assert "4x4" in capsys.readouterr().err
    assert not (tmp_path / "v.png").exists()


def test_dataset_every_below_one_is_refused(tiny_capture, tmp_path):
    assert (
        main(
            ["dataset", "--capture", str(tiny_capture), "--out", str(tmp_path / "ds"), "--every", "0", "--no-progress"]
        )
        == 2
    )
    with pytest.raises(ValueError, match="every"):
        capture_to_dataset(tiny_capture, tmp_path / "ds", every=0, progress=False)
    assert not (tmp_path / "ds").exists()


def test_dataset_lists_the_key_frames_it_dropped(tiny_capture, tmp_path):
    ds = capture_to_dataset(tiny_capture, tmp_path / "ds", every=2, images="truth", progress=False)
    assert ds.meta["source"]["key_frames_dropped"] == ["00005", "00007"]  # key frames 0, 5, 7 of 8 frames


def test_dataset_refuses_a_video_that_disagrees_with_the_truth(tiny_capture, tmp_path):
    cap = tmp_path / "cap"
    shutil.copytree(tiny_capture, cap)
    transforms = json.loads((cap / "truth" / "transforms.json").read_text())
    transforms["frames"] = transforms["frames"][:-1]
    (cap / "truth" / "transforms.json").write_text(json.dumps(transforms))
    with pytest.raises(CaptureFolderError, match=r"video has 8 frames but truth/transforms\.json lists 7"):
        capture_to_dataset(cap, tmp_path / "ds", progress=False)


def test_dataset_of_a_millimetre_capture_keeps_its_units(tmp_path, small_spec):
    spec = small_spec(n_frames=2, width=32, height=24)
    spec.units.name, spec.units.per_metre = "mm", 1000.0
    cap = generate_capture(spec, tmp_path / "cap", progress=False)
    ds = capture_to_dataset(cap, tmp_path / "ds", images="truth", progress=False)
    assert (ds.meta["units"], ds.meta["units_per_metre"]) == ("mm", 1000.0)
    np.testing.assert_allclose(ds.scene_box, [[-2000, -1800, 0], [2000, 1800, 2500]])
