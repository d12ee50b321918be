"""`livescene control` and `livescene language query/relevancy` on a fake run (no training needed)."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
import yaml

from stages.language import cli as language_cli
from stages.language import control_cli
from stages.model import RunConfig
from stages.model import run as model_run_module


class _FakeRun:
    """The model API; the image's grey level is the first object's state so the render shows the command."""

    def __init__(self, objects, frame_ids=()):
        self.objects = objects
        self.frame_ids = list(frame_ids)  # empty: not checked against the dataset
        self.calls = []

    def state_vector(self, states, frame_index=None):  # a learned state of its own at every frame
        return np.full(len(self.objects), 0.25)

    def warn_if_states_unread(self, states):  # a method that reads states
        pass

    def check_dataset(self, ds):  # the dataset it was trained on
        pass

    def frame_index_of(self, frame, ds_frames):  # by id where the run records ids, as LoadedRun
        ids = self.frame_ids or [f.frame_id for f in ds_frames]
        return ids.index(frame.frame_id) if frame.frame_id in ids else None

    def render(self, camera, c2w, states, frame_index=None):
        self.calls.append((frame_index, dict(states)))
        h, w = camera.height, camera.width
        probs = np.zeros((h, w, len(self.objects) + 1), np.float32)
        probs[:, : w // 2, 0] = 1.0
        probs[:, w // 2 :, -1] = 1.0
        return {"rgb": np.full((h, w, 3), states[self.objects[0]], np.float32), "probs": probs}


def test_control_parse_only_without_encoder(capsys):
    code = control_cli.main(["--objects", "fridge,drawer", "--no-encoder", "--state", "drawer=0.4",
                             "open the fridge to 30% and close the drawr"])
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    assert out["states"] == {"fridge": 0.3, "drawer": 0.0} and out["vector"] == [0.3, 0.0]
    assert [a["method"] for a in out["actions"]] == ["exact", "fuzzy"]


def test_control_errors_exit_2_with_candidates(capsys):
    assert control_cli.main(["--objects", "fridge,drawer", "--no-encoder", "open the oven"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "unknown object \"oven\"" in err and "fridge (spelling" in err
    assert control_cli.main(["--objects", "fridge", "--no-encoder", "--state", "fridge", "open all"]) == 2
    assert "OBJECT=VALUE" in capsys.readouterr().err
    assert control_cli.main(["--objects", "fridge", "--no-encoder", "--state", "fridge=nan", "open all"]) == 2
    assert "'fridge=nan': state nan is not in [0, 1]" in capsys.readouterr().err
    assert control_cli.main(["--no-encoder", "open all"]) == 2
    assert "no object names" in capsys.readouterr().err


def test_control_with_a_run_renders_the_result(tiny_dataset, tmp_path, monkeypatch, capsys, encoder):
    fake = _FakeRun(tiny_dataset.objects)
    monkeypatch.setattr(model_run_module, "open_run", lambda run, device="cpu": fake)
    monkeypatch.setattr(control_cli, "encoder_from_args", lambda args: encoder)
    (tmp_path / "run").mkdir()
    out_png = tmp_path / "result.png"
    code = control_cli.main(["--run", str(tmp_path / "run"), "--data", str(tiny_dataset.root), "--out", str(out_png),
                             "half open thing zero"])  # "thing zero" is object0's synonym in the fixture
    assert code == 0
    report = json.loads(capsys.readouterr().out)
    assert report["states"]["object0"] == 0.5 and report["frame"] == "00000"  # first test frame
    assert fake.calls == [(0, report["states"])]
    img = cv2.imread(str(out_png))
    assert img.shape == (12, 16, 3) and int(img[0, 0, 0]) == 128


def test_control_from_a_frame_starts_from_the_runs_states_and_needs_its_dataset(tiny_dataset, tmp_path, monkeypatch,
                                                                                capsys):
    """--from-frame with a run starts from what the run renders there (learned states too), and a dataset of other
    frames than the run's (whose frame index would mean another frame) is refused."""
    fake = _FakeRun(tiny_dataset.objects, [f.frame_id for f in tiny_dataset.frames])
    monkeypatch.setattr(model_run_module, "open_run", lambda run, device="cpu": fake)
    (tmp_path / "run").mkdir()
    args = ["--run", str(tmp_path / "run"), "--data", str(tiny_dataset.root), "--no-encoder", "--from-frame",
            "--out", str(tmp_path / "c.png"), "open object1"]
    assert control_cli.main(args) == 0
    states = json.loads(capsys.readouterr().out)["states"]
    assert states == {"object0": 0.25, "object1": 1.0, "object2": 0.25}  # the run's 0.25, not the dataset's
    fake.frame_ids = ["99999", *fake.frame_ids[1:]]
    assert control_cli.main(args) == 2
    assert "is not the dataset the run was trained on" in capsys.readouterr().err


def test_control_names_a_state_beyond_the_training_frames(tiny_dataset):
    # the capture only half opened object0: asked for 1, the render extrapolates, and control says so
    for k, f in enumerate(tiny_dataset.frames_in("train")):
        f.state = {"object0": 0.4 * (k % 2), "object1": float(k % 2), "object2": float(k % 2)}
    beyond = control_cli._beyond_training(tiny_dataset, {"object0": 1.0, "object1": 1.0, "object2": 0.5})
    assert beyond == {"object0": {"state": 1.0, "training_range": [0.0, 0.4]}}
    assert control_cli._beyond_training(tiny_dataset, {"object0": 0.5, "object1": 0.0, "object2": 1.0}) == {}
    # below the range too, with the same margin (0.125): a drawer the capture never closed further than 0.4
    for k, f in enumerate(tiny_dataset.frames_in("train")):
        f.state = {"object0": (0.4, 0.5)[k % 2], "object1": 0.0, "object2": 0.0}
    assert control_cli._beyond_training(tiny_dataset, {"object0": 0.3, "object1": 0.0, "object2": 0.0}) == {}
    assert control_cli._beyond_training(tiny_dataset, {"object0": 0.2, "object1": 0.0, "object2": 0.0}) == {
        "object0": {"state": 0.2, "training_range": [0.4, 0.5]}}


def test_language_query_and_relevancy(tiny_dataset, tmp_path, monkeypatch, capsys, encoder):
    monkeypatch.setattr(language_cli, "encoder_from_args", lambda args: encoder)
    assert language_cli.main(["query", "--data", str(tiny_dataset.root), "thing zero"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["resolved"] == {"object": "object0", "method": "exact", "score": 1.0}
    assert set(out["embedding"]) == set(tiny_dataset.objects)

    monkeypatch.setattr(model_run_module, "open_run", lambda run, device="cpu": _FakeRun(tiny_dataset.objects))
    (tmp_path / "run").mkdir()
    png = tmp_path / "map.png"
    assert language_cli.main(["relevancy", "--run", str(tmp_path / "run"), "--data", str(tiny_dataset.root),
                              "--out", str(png), "thing zero"]) == 0
    info = json.loads(capsys.readouterr().out)
    rel = cv2.imread(str(png), cv2.IMREAD_GRAYSCALE)
    assert info["fraction_above_0.5"] == 0.5
    assert rel[:, :8].min() > 127 > rel[:, 8:].max()
    assert rel[:, :8].min() == 255 and rel[:, 8:].max() == 0  # "thing zero" names object0: its probability, 1 or 0
    assert language_cli.main(["relevancy", "--run", str(tmp_path / "run"), "--data", str(tiny_dataset.root),
                              "--out", str(png), "--source", "language", "thing zero"]) == 2
    assert "renders no language embedding" in capsys.readouterr().err
    assert language_cli.main(["relevancy", "--run", str(tmp_path / "run"), "--data", str(tiny_dataset.root),
                              "--out", str(png), " "]) == 2
    assert "the text query is empty" in capsys.readouterr().err
    assert info["matched_object"] == "object0" and info["matched_by"] == "name"
    assert info["object_weights"]["object0"] == 1.0
    # a query that names nothing still lights up its nearest object (the weights are a softmax): said so
    assert language_cli.main(["relevancy", "--run", str(tmp_path / "run"), "--data", str(tiny_dataset.root),
                              "--out", str(png), "xyzzy qwerty"]) == 0
    captured = capsys.readouterr()
    assert json.loads(captured.out)["matched_object"] is None
    assert '"xyzzy qwerty" names no object of the scene' in captured.err
    assert language_cli.main(["query", "--data", str(tiny_dataset.root), "  "]) == 2
    assert "the phrase is empty" in capsys.readouterr().err


def test_relevancy_refuses_a_query_space_the_language_table_was_not_trained_in(tiny_dataset, tmp_path, monkeypatch,
                                                                               capsys, encoder):
    monkeypatch.setattr(language_cli, "encoder_from_args", lambda args: encoder)

    class OtherSpace(_FakeRun):
        language_encoder = "an OpenCLIP text tower"

        def render(self, camera, c2w, states, frame_index=None):
            out = super().render(camera, c2w, states, frame_index)
            return {**out, "language": np.ones((camera.height, camera.width, 384), np.float32)}

    monkeypatch.setattr(model_run_module, "open_run", lambda run, device="cpu": OtherSpace(tiny_dataset.objects))
    (tmp_path / "run").mkdir()
    assert language_cli.main(["relevancy", "--run", str(tmp_path / "run"), "--data", str(tiny_dataset.root),
                              "--out", str(tmp_path / "m.png"), "--source", "language", "thing zero"]) == 2
    assert "trained with encoder 'an OpenCLIP text tower'" in capsys.readouterr().err


def test_control_out_without_a_run_is_refused(capsys):
    assert control_cli.main(["open object0", "--objects", "object0", "--out", "c.png"]) == 2
    assert "--out: a render needs a trained run" in capsys.readouterr().err


def _run_folder(root, data):
    """A run folder whose config.yaml is a RunConfig (as `livescene train` writes it) naming ``data``."""
    run = root / "run"
    run.mkdir()
    (run / "config.yaml").write_text(yaml.safe_dump(RunConfig(data=str(data)).to_dict()))
    return run


def test_control_finds_the_runs_dataset_in_its_config(tiny_dataset, tmp_path, monkeypatch, capsys):
    fake = _FakeRun(tiny_dataset.objects)
    monkeypatch.setattr(model_run_module, "open_run", lambda run, device="cpu": fake)
    run = _run_folder(tmp_path, tiny_dataset.root)
    assert model_run_module.run_dataset_root(run) == tiny_dataset.root  # RunConfig.data, as written
    assert control_cli.main(["--run", str(run), "--no-encoder", "--out", str(tmp_path / "c.png"),
                             "open object1"]) == 0
    assert json.loads(capsys.readouterr().out)["states"]["object1"] == 1.0 and fake.calls


@pytest.mark.parametrize("cli", ["control", "relevancy"])
def test_a_run_whose_dataset_moved_or_is_unnamed_is_refused_with_the_fix(tmp_path, capsys, cli):
    def call(run):
        if cli == "control":
            return control_cli.main(["--run", str(run), "--no-encoder", "open all"])
        return language_cli.main(["relevancy", "--run", str(run), "--out", str(tmp_path / "m.png"), "thing"])

    run = _run_folder(tmp_path, tmp_path / "moved-away")
    assert call(run) == 2
    err = capsys.readouterr().err
    assert f"{run / 'config.yaml'}: names the dataset {tmp_path / 'moved-away'}, which is not there" in err
    assert "fix: pass --data DS (the dataset the run was trained on)" in err
    (run / "config.yaml").write_text(yaml.safe_dump(RunConfig().to_dict()))  # data: ""
    assert call(run) == 2
    assert "config.yaml: does not say which dataset the run was trained on; fix: pass --data DS" in \
        capsys.readouterr().err
    assert call(tmp_path / "no-run") == 2
    assert "no-run: run folder not found; fix: train one with `livescene train" in capsys.readouterr().err


def test_control_starts_from_a_frames_states_without_a_run(tiny_dataset, capsys):
    # parse only (no run): --from-frame --frame takes that frame's states, which "except" then keeps
    frame = tiny_dataset.frames[1]
    assert frame.state and any(v > 0 for v in frame.state.values())
    kept = max(frame.state, key=frame.state.get)
    code = control_cli.main(["--data", str(tiny_dataset.root), "--no-encoder", "--from-frame", "--frame",
                             frame.frame_id, f"close everything except {kept}"])
    assert code == 0
    states = json.loads(capsys.readouterr().out)["states"]
    assert states[kept] == pytest.approx(frame.state[kept]) and states[kept] > 0
    assert all(v == 0.0 for name, v in states.items() if name != kept)


def test_control_refuses_a_frame_without_a_dataset(capsys):
    assert control_cli.main(["--objects", "fridge,drawer", "--no-encoder", "--from-frame", "open all"]) == 2
    assert "a frame needs a scene dataset" in capsys.readouterr().err


def test_no_cache_loads_the_encoder_without_a_cache_folder(monkeypatch, tmp_path):
    from stages.language import encoder as encoder_module

    seen = []
    monkeypatch.setattr(encoder_module, "load_encoder",
                        lambda kind, path, cache_dir, clip_model: seen.append(cache_dir))
    parser = language_cli.build_parser()
    language_cli.encoder_from_args(parser.parse_args(["query", "--data", "d", "--no-cache", "x"]))
    language_cli.encoder_from_args(parser.parse_args(["query", "--data", "d", "--cache", str(tmp_path), "x"]))
    assert seen == [None, tmp_path]
