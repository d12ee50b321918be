"""`livescene capture`: generate (no clobbering, nothing lost on failure), render, spec errors."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from stages.capture import CaptureSpecError, load_spec, spec_to_dict
from stages.capture.cli import main
from stages.capture.renderer import SceneRenderer


@pytest.fixture
def spec_file(tmp_path, small_spec) -> Path:
    path = tmp_path / "small.yaml"
    path.write_text(yaml.safe_dump(spec_to_dict(small_spec(n_frames=3, width=40, height=30))))
    return path


def test_generate_refuses_to_clobber_and_force_replaces(tmp_path, spec_file, capsys):
    out = tmp_path / "cap"
    out.mkdir()
    (out / "notes.txt").write_text("precious")
    assert main(["--spec", str(spec_file), "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "--force" in err
    assert (out / "notes.txt").read_text() == "precious"
    assert main(["--spec", str(spec_file), "--out", str(out), "--force", "--no-progress"]) == 0
    assert not (out / "notes.txt").exists()
    assert json.loads((out / "capture.json").read_text())["n_frames"] == 3


def test_generate_into_an_empty_folder_is_allowed(tmp_path, spec_file):
    out = tmp_path / "empty"
    out.mkdir()
    assert main(["--spec", str(spec_file), "--out", str(out), "--no-progress"]) == 0
    assert (out / "video.mp4").is_file()


def test_a_failed_run_leaves_the_old_capture_untouched(tmp_path, spec_file, monkeypatch):
    out = tmp_path / "cap"
    out.mkdir()
    (out / "notes.txt").write_text("precious")
    calls = {"n": 0}
    original = SceneRenderer.render

    def failing(self, *args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 2:
            raise RuntimeError("simulated crash in the middle of the capture")
        return original(self, *args, **kwargs)

    monkeypatch.setattr(SceneRenderer, "render", failing)
    with pytest.raises(RuntimeError, match="simulated crash"):
        main(["--spec", str(spec_file), "--out", str(out), "--force", "--no-progress"])
    assert [p.name for p in out.iterdir()] == ["notes.txt"]
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".cap")] == []  # no temporary left behind


def test_render_cli_reproduces_a_truth_frame_and_takes_new_states(tiny_capture, tmp_path, capsys):
    png = tmp_path / "view.png"
    assert main(["render", "--capture", str(tiny_capture), "--pose", "4", "--out", str(png)]) == 0
    truth_rgb = cv2.imread(str(tiny_capture / "truth" / "images" / "frame_00004.png"))
    assert np.array_equal(cv2.imread(str(png)), truth_rgb)
    assert np.array_equal(np.load(tmp_path / "view.depth.npy"),
                          np.load(tiny_capture / "truth" / "depth" / "frame_00004.npy"))
    assert np.array_equal(cv2.imread(str(tmp_path / "view.ids.png"), cv2.IMREAD_UNCHANGED),
                          cv2.imread(str(tiny_capture / "masks" / "frame_00004.png"), cv2.IMREAD_UNCHANGED))
    # the same pose from a .npy file, with the cabinet opened: only the states differ
    frames = json.loads((tiny_capture / "truth" / "transforms.json").read_text())["frames"]
    np.save(tmp_path / "pose.npy", np.asarray(frames[4]["transform_matrix"]))
    other = tmp_path / "open.png"
    assert main(["render", "--capture", str(tiny_capture), "--pose", str(tmp_path / "pose.npy"),
                 "--states", "cabinet=1", f"drawer={frames[4]['state']['drawer']}", "--out", str(other)]) == 0
    printed = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert printed["states"]["cabinet"] == 1.0
    assert not np.array_equal(cv2.imread(str(other)), truth_rgb)
    assert main(["render", "--capture", str(tiny_capture), "--pose", "4", "--states", "window=1",
                 "--out", str(other)]) == 2
    assert "window" in capsys.readouterr().err


@pytest.mark.parametrize(("edit", "key"), [
    (lambda d: d["objects"][1].update(kind="window"), "objects[1] (drawer): kind"),
    (lambda d: d["camera"].update(radius_m=2.0), "spec.camera has unknown keys ['radius_m']"),
    (lambda d: d["objects"][0]["schedule"].update(keys=[[0.5, 0.0], [0.2, 1.0]]), "objects[0] (cabinet): schedule"),
    (lambda d: d["video"].update(width=4), "video"),
])
def test_spec_errors_name_the_file_and_the_key(tmp_path, edit, key, capsys):
    data = yaml.safe_load((Path(__file__).resolve().parents[2] / "config/captures/tiny.yaml").read_text())
    edit(data)
    path = tmp_path / "broken.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(CaptureSpecError) as info:
        load_spec(path)
    assert str(path) in str(info.value) and key in str(info.value)
    assert main(["--spec", str(path), "--out", str(tmp_path / "out"), "--no-progress"]) == 2
    assert str(path) in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("preset", ["demo", "tiny", "kitchen", "stress", "stiff", "extreme"])
def test_presets_load(preset):
    spec = load_spec(Path(__file__).resolve().parents[2] / "config" / "captures" / f"{preset}.yaml")
    assert spec.name == preset and spec.objects
