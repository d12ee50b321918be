"""Commands that read a trained run never overwrite what they read, and say clearly what they cannot do."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from stages.language import cli as language_cli
from stages.language import control_cli
from stages.model.render_cli import main as render_main
from stages.scene import InputError
from stages.scene.atomic_io import guard_output_file


def test_a_single_file_output_is_refused_inside_an_input_or_of_another_kind(tmp_path: Path):
    run = tmp_path / "run"
    run.mkdir()
    (run / "model.pt").write_bytes(b"weights")
    with pytest.raises(InputError, match=r"is no \.png file name.*fix: give --out a name ending in \.png"):
        guard_output_file(run / "model.pt", "the control render", suffixes=(".png",), inputs=[run])
    with pytest.raises(InputError, match=r"lies inside the input .*run.*fix: choose an --out outside the inputs"):
        guard_output_file(run / "view.png", "the control render", suffixes=(".png",), inputs=[run, None])
    guard_output_file(tmp_path / "view.PNG", "the control render", suffixes=(".png",), inputs=[run])  # fine
    assert (run / "model.pt").read_bytes() == b"weights"


def test_control_and_relevancy_refuse_an_out_in_the_run(trained_run: Path, capsys):
    weights = (trained_run / "model.pt").read_bytes()
    assert control_cli.main(["--run", str(trained_run), "--no-encoder", "open everything",
                             "--out", str(trained_run / "model.pt")]) == 2
    assert "is no .png file name" in capsys.readouterr().err
    assert language_cli.main(["relevancy", "--run", str(trained_run), "object0",
                              "--out", str(trained_run / "map.png")]) == 2
    assert "lies inside the input" in capsys.readouterr().err
    assert (trained_run / "model.pt").read_bytes() == weights and not (trained_run / "map.png").exists()


def test_a_video_render_never_deletes_files_it_did_not_render(trained_run: Path, tmp_path: Path, capsys):
    images = tmp_path / "images"  # a dataset's images, named as a video's frames are
    images.mkdir()
    for j in range(3):
        (images / f"frame_{j:05d}.png").write_bytes(b"not ours")
    args = ["--run", str(trained_run), "--orbit", "--fps", "2", "--seconds", "1", "--width", "16", "--height", "12",
            "--no-progress"]
    assert render_main([*args, "--frames-dir", str(images), "--out", str(tmp_path / "v.mp4")]) == 2
    assert "not an earlier video render's frames" in capsys.readouterr().err
    assert sorted(p.name for p in images.iterdir()) == [f"frame_{j:05d}.png" for j in range(3)]
    assert render_main([*args, "--out", str(trained_run / "model.pt")]) == 2
    assert "is no .mp4" in capsys.readouterr().err
    assert render_main([*args, "--out", str(tmp_path / "v.mp4")]) == 0  # its own frame folder, reused below
    frames = json.loads(capsys.readouterr().out)["frames_dir"]
    assert render_main([*args, "--out", str(tmp_path / "v.mp4")]) == 0
    assert json.loads(capsys.readouterr().out)["frames_dir"] == frames


def test_a_cuda_device_without_cuda_is_named(trained_run: Path, capsys):
    import torch

    if torch.cuda.is_available():
        pytest.skip("this machine has CUDA")
    assert render_main(["--run", str(trained_run), "--orbit", "--out", "x.mp4", "--device", "cuda"]) == 2
    assert "CUDA requested but torch sees no GPU" in capsys.readouterr().err


def test_a_sweep_refuses_a_dataset_of_other_frames_than_the_runs(trained_run: Path, tiny_dataset, tmp_path: Path):
    import shutil

    from stages.report.sweep import render_sweeps

    other = tmp_path / "other"
    shutil.copytree(tiny_dataset.root, other)
    data = json.loads((other / "transforms.json").read_text())
    data["frames"] = data["frames"][1:]  # one frame fewer: every later frame index now names the next frame
    (other / "key_frame_value.yaml").unlink(missing_ok=True)
    for key in ("train_filenames", "val_filenames", "test_filenames"):
        data.pop(key, None)
    (other / "transforms.json").write_text(json.dumps(data))
    with pytest.raises(InputError, match="is not the dataset the run was trained on"):
        render_sweeps(trained_run, other, tmp_path / "sweep", steps=2, scale=0.5, progress=False)
    assert not (tmp_path / "sweep").exists()
