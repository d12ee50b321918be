"""A checkpoint resumes only onto the data and config it was trained on; a stale one is refused or restarted."""

from __future__ import annotations

import csv
import io
import json
import shutil
from pathlib import Path

import pytest
import torch
import yaml

from stages.model import Trainer, run_inputs
from stages.model.run_inputs import code_digest, config_differences, data_digest
from stages.model.train_cli import main as train_main
from stages.scene import InputError


def _finished(config, out):
    Trainer(config, out, device="cpu", progress=False).train()
    return json.loads((out / "run.json").read_text())


def _moved_pose_copy(src, dst):
    """The dataset with one camera moved by 1 cm: what a re-estimation of the poses does."""
    shutil.copytree(src, dst)
    path = dst / "transforms.json"
    data = json.loads(path.read_text())
    data["frames"][0]["transform_matrix"][0][3] += 0.01
    path.write_text(json.dumps(data))
    return dst


def test_resume_onto_moved_poses_is_refused_naming_the_data(tiny_dataset, tmp_path, tiny_config):
    out = tmp_path / "run"
    first = _finished(tiny_config(tiny_dataset.root, steps=3), out)
    moved = _moved_pose_copy(tiny_dataset.root, tmp_path / "moved")
    with pytest.raises(InputError, match="training data differ") as err:
        Trainer(tiny_config(moved, steps=3), out, device="cpu", progress=False, resume=True).train()
    assert "--restart-stale" in str(err.value)
    # nothing of the old run was touched
    assert json.loads((out / "run.json").read_text()) == first
    assert (out / "checkpoints" / "step_000003.pt").is_file()


def test_restart_stale_trains_from_step_zero_on_the_new_data(tiny_dataset, tmp_path, tiny_config):
    out = tmp_path / "run"
    first = _finished(tiny_config(tiny_dataset.root, steps=3), out)
    moved = _moved_pose_copy(tiny_dataset.root, tmp_path / "moved")
    fresh = tmp_path / "fresh"
    expected = _finished(tiny_config(moved, steps=3), fresh)
    assert expected["data_digest"] != first["data_digest"]

    Trainer(tiny_config(moved, steps=3), out, device="cpu", progress=False, resume=True, restart_stale=True).train()
    run = json.loads((out / "run.json").read_text())
    assert run["data_digest"] == expected["data_digest"] and run["steps"] == 3
    with (out / "train_log.csv").open() as fh:
        assert [int(r["step"]) for r in csv.DictReader(fh)] == [1, 2, 3]
    a = torch.load(out / "model.pt", weights_only=True)["state_dict"]
    b = torch.load(fresh / "model.pt", weights_only=True)["state_dict"]
    for k in a:  # the restarted run is the run a fresh folder gives
        torch.testing.assert_close(a[k], b[k], rtol=0, atol=0, equal_nan=True, msg=k)


def test_config_change_is_named_and_more_steps_are_another_run(tiny_dataset, tmp_path, tiny_config):
    out = tmp_path / "run"
    _finished(tiny_config(tiny_dataset.root, steps=3), out)
    with pytest.raises(InputError, match=r"config differs in train\.lr"):
        Trainer(tiny_config(tiny_dataset.root, "train.lr=0.001", steps=3), out, device="cpu", progress=False,
                resume=True).train()
    # the learning rate decays over max_steps, and the thread count orders the float sums: other runs
    for change in (["train.threads=3"], ["train.max_seconds=100"]):
        with pytest.raises(InputError, match="config differs in train"):
            Trainer(tiny_config(tiny_dataset.root, *change, steps=3), out, device="cpu", progress=False,
                    resume=True).train()
    with pytest.raises(InputError, match=r"config differs in train\.max_steps"):
        Trainer(tiny_config(tiny_dataset.root, steps=5), out, device="cpu", progress=False, resume=True).train()
    fresh = tmp_path / "fresh"
    _finished(tiny_config(tiny_dataset.root, steps=5), fresh)
    Trainer(tiny_config(tiny_dataset.root, steps=5), out, device="cpu", progress=False, resume=True,
            restart_stale=True).train()
    with (out / "train_log.csv").open() as fh:
        assert [int(r["step"]) for r in csv.DictReader(fh)] == [1, 2, 3, 4, 5]
    a = torch.load(out / "model.pt", weights_only=True)["state_dict"]
    b = torch.load(fresh / "model.pt", weights_only=True)["state_dict"]
    for k in a:  # five steps from step 0, as a fresh folder trains them: not three resumed under another schedule
        torch.testing.assert_close(a[k], b[k], rtol=0, atol=0, equal_nan=True, msg=k)


def test_a_finished_run_rerun_with_nothing_to_train_keeps_its_records(tiny_dataset, tmp_path, tiny_config):
    """A workflow rerun after a setting of how a run runs changed (a trust floor, the render chunk) trains nothing:
    its run.json (eval PSNR, peak memory) and model.pt stay the training's, even though Snakemake deleted run.json
    before the job ran; config.yaml takes the new floors. eval_every is the run's log: a change trains again."""
    out = tmp_path / "run"
    _finished(tiny_config(tiny_dataset.root, steps=3), out)
    before = json.loads((out / "run.json").read_text())
    weights = (out / "model.pt").read_bytes()
    (out / "run.json").unlink()  # Snakemake removes a job's outputs before it runs
    Trainer(tiny_config(tiny_dataset.root, "train.render_chunk=777", "trust.min_steps=2", steps=3), out,
            device="cpu", progress=False, resume=True, restart_stale=True).train()
    assert json.loads((out / "run.json").read_text()) == before and before["eval_psnr"] is not None
    assert (out / "model.pt").read_bytes() == weights
    config = yaml.safe_load((out / "config.yaml").read_text())
    assert config["trust"]["min_steps"] == 2 and config["train"]["render_chunk"] != 777
    with pytest.raises(InputError, match=r"config differs in train\.eval_every"):
        Trainer(tiny_config(tiny_dataset.root, "train.eval_every=1", steps=3), out, device="cpu", progress=False,
                resume=True).train()


def test_a_checkpoint_of_other_code_is_another_run(tiny_dataset, tmp_path, tiny_config, monkeypatch):
    """`snakemake --forcerun train` after the model code changed: the finished checkpoint must not stand in for the
    training asked for (the same inputs and config, other code); on unchanged code it is kept, as training is
    deterministic."""
    import stages.model.trainer as trainer_module

    out = tmp_path / "run"
    first = _finished(tiny_config(tiny_dataset.root, steps=3), out)
    assert first["code_digest"] == code_digest()
    weights = (out / "model.pt").read_bytes()
    monkeypatch.setattr(trainer_module, "code_digest", lambda: "0" * 64)  # the code as edited since
    with pytest.raises(InputError, match=r"trained by other code \(stages/model or stages/scene changed"):
        Trainer(tiny_config(tiny_dataset.root, steps=3), out, device="cpu", progress=False, resume=True).train()
    (out / "run.json").unlink()  # Snakemake removes a job's outputs before it runs
    Trainer(tiny_config(tiny_dataset.root, steps=3), out, device="cpu", progress=False, resume=True,
            restart_stale=True).train()
    with (out / "train_log.csv").open() as fh:  # trained again from step 0, not "nothing to train"
        assert [int(r["step"]) for r in csv.DictReader(fh)] == [1, 2, 3]
    assert json.loads((out / "run.json").read_text())["code_digest"] == "0" * 64
    a = torch.load(out / "model.pt", weights_only=True)["state_dict"]
    b = torch.load(io.BytesIO(weights), weights_only=True)["state_dict"]
    for k in a:  # the "edited" code is the same code here, so training again gives the same bits
        torch.testing.assert_close(a[k], b[k], rtol=0, atol=0, equal_nan=True, msg=k)


def test_the_code_digest_follows_the_model_and_scene_code_only(tmp_path):
    stages = Path(run_inputs.__file__).resolve().parents[1]
    copy = tmp_path / "stages"
    for package in ("model", "scene", "report"):
        shutil.copytree(stages / package, copy / package, ignore=shutil.ignore_patterns("__pycache__"))
    assert code_digest(copy) == code_digest()  # the same files give the same digest, wherever they lie
    (copy / "report" / "__init__.py").write_text("# not training code\n")
    code_digest.cache_clear()  # computed once per process and folder: the code a training loaded
    assert code_digest(copy) == code_digest()
    edited = copy / "model" / "losses.py"
    edited.write_text(edited.read_text() + "# a comment\n")
    code_digest.cache_clear()
    changed = code_digest(copy)
    assert changed != code_digest()
    (copy / "scene" / "new_reader.py").write_text("")
    code_digest.cache_clear()
    assert code_digest(copy) not in (changed, code_digest())


def test_cli_restart_stale_flag(tiny_dataset, tmp_path, tiny_overrides, capsys):
    out = tmp_path / "run"
    sets = [a for o in tiny_overrides for a in ("--set", o)]
    base = ["--method", "livescene", "--preset", "cpu-demo", "--out", str(out), "--max-steps", "2", "--device", "cpu",
            "--no-progress", *sets]
    assert train_main(["--data", str(tiny_dataset.root), *base]) == 0
    moved = _moved_pose_copy(tiny_dataset.root, tmp_path / "moved")
    assert train_main(["--data", str(moved), "--resume", *base]) != 0
    assert "cannot resume" in capsys.readouterr().err
    assert train_main(["--data", str(moved), "--resume", "--restart-stale", *base]) == 0
    assert "starting over" in capsys.readouterr().err


def test_digest_and_differences_helpers():
    a = {"x": torch.arange(4, dtype=torch.float32), "y": None}
    assert data_digest(a) == data_digest({"y": None, "x": torch.arange(4, dtype=torch.float32)})
    assert data_digest(a) != data_digest({"x": torch.arange(4, dtype=torch.float64), "y": None})
    old = {"seed": 0, "data": "a", "train": {"lr": 0.02, "render_chunk": 10}, "trust": {"min_psnr": 20.0}}
    new = {"seed": 1, "data": "b", "train": {"lr": 0.02, "render_chunk": 99}, "trust": {"min_psnr": 5.0}}
    assert config_differences(old, new) == ["seed"]
    # a checkpoint written before train.compile_mode existed resumes under any mode: how it runs, not what it learns
    new["train"]["compile_mode"] = "reduce-overhead"
    assert config_differences(old, new) == ["seed"]
