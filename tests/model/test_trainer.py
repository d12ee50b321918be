"""Trainer: resume is bit-exact on CPU, SIGTERM saves a checkpoint, non-finite steps are skipped, logs and run.json."""

from __future__ import annotations

import csv
import json
import os
import signal

import numpy as np
import pytest
import torch

from stages.model import Trainer, TrainingDiverged, load_run
from stages.model.train_cli import main as train_main


def _weights(run_dir):
    return torch.load(run_dir / "model.pt", weights_only=True)["state_dict"]


def test_resume_after_sigterm_is_bit_identical(tiny_dataset, tmp_path, tiny_config, capsys):
    config = tiny_config(tiny_dataset.root, "train.eval_every=4", steps=5)  # the stop (step 2) is off the grid
    straight = tmp_path / "straight"
    Trainer(config, straight, device="cpu", progress=False).train()

    interrupted = tmp_path / "interrupted"
    trainer = Trainer(config, interrupted, device="cpu", progress=False)
    original = trainer.train_step

    def step_then_signal():
        result = original()
        if trainer.step == 1:  # during the 2nd step: a real SIGTERM arrives
            os.kill(os.getpid(), signal.SIGTERM)
        return result

    trainer.train_step = step_then_signal
    summary = trainer.train()
    assert summary == {"status": "sigterm", "step": 2}
    assert (interrupted / "checkpoints" / "step_000002.pt").is_file()
    assert not (interrupted / "model.pt").exists()
    with pytest.raises(Exception, match="--resume"):
        Trainer(config, interrupted, device="cpu", progress=False).train()

    Trainer(config, interrupted, device="cpu", progress=False, resume=True).train()
    assert f"{interrupted}: resumed from step_000002.pt at step 2" in capsys.readouterr().err  # the job's log says so
    a, b = _weights(straight), _weights(interrupted)
    assert a.keys() == b.keys()
    for k in a:
        torch.testing.assert_close(a[k], b[k], rtol=0, atol=0, equal_nan=True, msg=k)
    with (interrupted / "train_log.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert [int(r["step"]) for r in rows] == [1, 2, 3, 4, 5]
    with (straight / "train_log.csv").open() as fh:  # the same held-out points: none at the stop step
        assert [(r["step"], r["eval_psnr"]) for r in csv.DictReader(fh)] == [(r["step"], r["eval_psnr"]) for r in rows]


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGHUP])
def test_ctrl_c_and_a_closed_terminal_stop_as_sigterm_does(tiny_dataset, tmp_path, tiny_config, sig):
    """Ctrl-C (SIGINT) and a closed terminal (SIGHUP) leave a checkpoint and a resumable run, as SIGTERM does; a
    second signal while the last checkpoint is written changes nothing."""
    out = tmp_path / "run"
    trainer = Trainer(tiny_config(tiny_dataset.root, steps=5), out, device="cpu", progress=False)
    original_step, original_save = trainer.train_step, trainer.save_checkpoint

    def step_then_signal():
        result = original_step()
        if trainer.step == 1:
            os.kill(os.getpid(), sig)
        return result

    def save_under_a_second_signal(*args, **kwargs):
        os.kill(os.getpid(), sig)  # the user presses Ctrl-C again
        return original_save(*args, **kwargs)

    trainer.train_step, trainer.save_checkpoint = step_then_signal, save_under_a_second_signal
    before = signal.getsignal(sig)
    assert trainer.train() == {"status": "sigterm", "step": 2} and trainer.stop_signal == sig
    assert (out / "checkpoints" / "step_000002.pt").is_file() and not (out / "model.pt").exists()
    assert signal.getsignal(sig) == before  # the caller's handler is back


def test_the_cli_names_the_signal_and_exits_with_its_code(monkeypatch, capsys, tmp_path):
    from stages.model import train_cli

    class Stopped:
        stop_signal = signal.SIGINT

        def __init__(self, *args, **kwargs):
            pass

        def train(self):
            return {"status": "sigterm", "step": 7}

    monkeypatch.setattr(train_cli, "Trainer", Stopped)
    monkeypatch.setattr(train_cli, "load_config", lambda *a, **k: None)
    assert train_cli.main(["--data", str(tmp_path), "--out", str(tmp_path / "run")]) == 130
    assert "stopped by SIGINT at step 7; checkpoint saved, resume with --resume" in capsys.readouterr().err


def test_a_checkpoint_from_another_device_resumes_with_the_jitter_reseeded(tiny_dataset, tmp_path, tiny_config,
                                                                             capsys):
    """A run begun on a GPU and continued on a CPU (or back): the generator states of one device do not fit the
    other's generators, so the jitter is reseeded from the step; training goes on and says so."""
    first = tmp_path / "first"
    trainer = Trainer(tiny_config(tiny_dataset.root, "train.checkpoint_every=2", steps=4), first, device="cpu",
                      progress=False)
    original = trainer.train_step

    def step_then_stop():
        result = original()
        if trainer.step == 1:  # stopped after its second step, as a SIGTERM stops it
            trainer.request_stop("sigterm")
        return result

    trainer.train_step = step_then_stop
    trainer.train()
    ckpt = first / "checkpoints" / "step_000002.pt"
    state = torch.load(ckpt, weights_only=False)
    assert state["device_type"] == "cpu"
    # as a CUDA run writes it: its jitter generator's state is a Philox seed and offset (16 bytes)
    state["device_type"], state["rng"]["jitter"] = "cuda", torch.zeros(16, dtype=torch.uint8)
    weights = []
    for name in ("a", "b"):
        run = tmp_path / name
        (run / "checkpoints").mkdir(parents=True)
        torch.save(state, run / "checkpoints" / ckpt.name)
        summary = Trainer(tiny_config(tiny_dataset.root, "train.checkpoint_every=2", steps=4), run, device="cpu",
                          progress=False, resume=True).train()
        assert summary["steps"] == 4
        assert "written on cuda, training goes on on cpu with the sample jitter reseeded" in capsys.readouterr().err
        weights.append(_weights(run))
    for k in weights[0]:  # the reseeding is deterministic
        torch.testing.assert_close(weights[0][k], weights[1][k], rtol=0, atol=0, equal_nan=True, msg=k)
    # model.pt too, byte for byte: nothing in it names the run's folder or its temporary file (checkpoints hold
    # the wall time)
    assert (tmp_path / "a" / "model.pt").read_bytes() == (tmp_path / "b" / "model.pt").read_bytes()


def test_run_files_log_columns_and_run_json(trained_run):
    run = json.loads((trained_run / "run.json").read_text())
    assert run["steps"] == 4 and run["status"] == "completed" and run["device"] == "cpu"
    assert run["params"]["total"] == sum(v for k, v in run["params"].items() if k != "total")
    assert run["peak_memory_mib"] > 0 and run["train_seconds"] > 0
    assert run["objects"] == ["object0", "object1", "object2"]
    # the wall time comes with the machine it was measured on
    machine = run["machine"]
    assert machine["cpu"] and machine["logical_cores"] >= 1 and machine["torch"] == torch.__version__
    with (trained_run / "train_log.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 4
    for col in ("wall_s", "step", "loss", "rgb", "interlevel", "distortion", "plane_tv", "focal_mask", "repulsion",
                "l1_k_planes", "k_smoothness", "eval_psnr"):
        assert col in rows[0]
    assert not {"focal_mask_on", "mask_levels", "repulsion_margin"} & set(rows[0])  # settings, not loss terms
    assert rows[1]["eval_psnr"] and np.isfinite(float(rows[1]["eval_psnr"]))
    assert float(rows[-1]["wall_s"]) >= float(rows[0]["wall_s"])
    assert (trained_run / "config.yaml").is_file()


def test_nonfinite_loss_skips_steps_then_stops_without_saving(tiny_dataset, tmp_path, monkeypatch, tiny_config):
    cfg = tiny_config(tiny_dataset.root, "train.max_nonfinite=3", steps=10)
    trainer = Trainer(cfg, tmp_path / "nan", device="cpu", progress=False)
    before = {k: v.clone() for k, v in trainer.model.state_dict().items()}
    real = trainer.model.loss_dict

    def poisoned(*args, **kwargs):
        terms = real(*args, **kwargs)
        terms["rgb"] = terms["rgb"] * float("nan")
        return terms

    monkeypatch.setattr(trainer.model, "loss_dict", poisoned)
    with pytest.raises(TrainingDiverged, match="rgb"):
        trainer.train()
    assert not list((tmp_path / "nan").glob("checkpoints/*.pt"))
    for k, v in trainer.model.state_dict().items():  # skipped steps leave the weights untouched
        torch.testing.assert_close(v, before[k], rtol=0, atol=0, equal_nan=True, msg=k)


def test_learned_state_mode_supervises_key_frames(tiny_dataset, tmp_path, tiny_config):
    out = tmp_path / "learned"
    cfg = tiny_config(tiny_dataset.root, "model.state.mode=learned", steps=3)
    Trainer(cfg, out, device="cpu", progress=False).train()
    with (out / "train_log.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert rows[0]["state_mse"] and float(rows[0]["state_mse"]) > 0
    run = load_run(out)
    states = run.learned_states()
    assert states.shape == (6, 3) and np.all((states > 0) & (states < 1))


def test_a_room_without_objects_trains_as_a_static_field(tiny_dataset, tmp_path, tiny_config):
    """A video filmed without masks or key frames (the workflow asks for learned states when a scene has no key
    frames): no object, so no state to learn; it trains as given and renders."""
    import shutil

    from stages.scene import read_scene, write_scene

    ds = tiny_dataset
    shutil.rmtree(ds.root / "masks")
    (ds.root / "mapping.yaml").unlink(missing_ok=True)
    ds.objects, ds.object_ids, ds.key_frames, ds.prompts = [], [], {}, {}
    for f in ds.frames:
        f.state = None
    write_scene(ds, ds.root)
    assert read_scene(ds.root).objects == []
    out = tmp_path / "static"
    Trainer(tiny_config(ds.root, "model.state.mode=learned", steps=2), out, device="cpu", progress=False).train()
    assert json.loads((out / "run.json").read_text())["state_mode"] == "given"
    run = load_run(out)
    frame = ds.frames[0]
    assert np.isfinite(run.render(ds.camera, frame.c2w, {})["rgb"]).all()
    # the workflow's export states "all=0" and "all=1" name the room's one state: exported once
    from stages.export.exporter import ExportOptions, export_run
    from stages.export.state_spec import parse_state_string

    combos = [parse_state_string(t, run.objects) for t in ("all=0", "all=1")]
    exported = export_run(run, read_scene(ds.root), combos, tmp_path / "export", ExportOptions(views=2, resolution=32),
                          progress=False)
    assert [e["states"] for e in exported["exports"]] == [{}]


def test_language_targets_train_and_render(tiny_dataset, tmp_path, tiny_config):
    rng = np.random.default_rng(0)
    emb = rng.normal(size=(3, 2, 8)).astype(np.float32)
    targets = tmp_path / "targets.npz"
    np.savez(targets, objects=np.array(["object0", "object1", "object2"]), states=np.array([0.0, 1.0], np.float32),
             embeddings=emb, background=rng.normal(size=8).astype(np.float32), encoder=np.array("fake"))
    out = tmp_path / "lang"
    cfg = tiny_config(tiny_dataset.root, steps=2)
    cfg.language_targets = str(targets)
    Trainer(cfg, out, device="cpu", progress=False).train()
    with (out / "train_log.csv").open() as fh:
        assert float(next(csv.DictReader(fh))["language"]) > 0
    run = load_run(out)
    img = run.render(tiny_dataset.camera, tiny_dataset.frames[0].c2w, None, frame_index=0)
    assert img["language"].shape == (12, 16, 8)
    assert np.allclose(np.linalg.norm(img["language"], axis=-1), 1.0, atol=1e-4)


def test_train_cli_errors_and_success(tiny_dataset, tmp_path, capsys, tiny_overrides):
    assert train_main(["--data", str(tmp_path / "missing"), "--out", str(tmp_path / "r")]) == 2
    assert "error:" in capsys.readouterr().err
    assert train_main(["--data", str(tiny_dataset.root), "--out", str(tmp_path / "r"), "--method", "nope"]) == 2
    assert "nope" in capsys.readouterr().err
    assert train_main(["--data", str(tiny_dataset.root), "--out", str(tmp_path / "r"), "--set", "bogus.x=1"]) == 2
    args = ["--data", str(tiny_dataset.root), "--out", str(tmp_path / "ok"), "--max-steps", "2", "--no-progress",
            "--device", "cpu", "--seed", "3"]
    for item in tiny_overrides:
        args += ["--set", item]
    assert train_main(args) == 0
    assert json.loads(capsys.readouterr().out.strip().splitlines()[-1])["steps"] == 2


def test_a_dataset_whose_split_frames_are_all_test_frames_is_refused(tiny_dataset, tmp_path, tiny_config):
    import shutil

    from stages.scene import SceneError

    root = tmp_path / "ds"
    shutil.copytree(tiny_dataset.root, root)
    data = json.loads((root / "transforms.json").read_text())
    for frame in data["frames"]:
        frame["split"] = "test"
    data["test_filenames"] = data.pop("train_filenames", []) + data.get("test_filenames", [])
    (root / "transforms.json").write_text(json.dumps(data))
    with pytest.raises(SceneError, match=r"split frames are test frames.*fix: mark the training frames"):
        Trainer(tiny_config(root, steps=2), tmp_path / "run", device="cpu", progress=False)


def test_objects_without_any_mask_are_refused_for_livescene(tiny_dataset, tmp_path, tiny_config):
    import shutil

    from stages.scene import SceneError

    root = tmp_path / "ds"
    shutil.copytree(tiny_dataset.root, root)
    shutil.rmtree(root / "masks")
    with pytest.raises(SceneError, match=r"names objects .* but no training frame has a mask.*fix: ingest masks"):
        Trainer(tiny_config(root, steps=2), tmp_path / "run", device="cpu", progress=False)
    Trainer(tiny_config(root, "method=mk-planes", steps=2), tmp_path / "mk", device="cpu", progress=False)


def test_a_finished_run_retrained_for_more_steps_is_unfinished_until_they_are_done(tiny_dataset, tmp_path,
                                                                                     tiny_config):
    """More steps are another run (the learning rate decays over them): it starts over, and until it is done the
    old run.json and model.pt no longer pose as its result."""
    out = tmp_path / "run"
    Trainer(tiny_config(tiny_dataset.root, steps=3), out, device="cpu", progress=False).train()
    assert (out / "run.json").is_file() and (out / "model.pt").is_file()
    trainer = Trainer(tiny_config(tiny_dataset.root, steps=5), out, device="cpu", progress=False, resume=True,
                      restart_stale=True)
    original = trainer.train_step

    def step_then_signal():
        result = original()
        if trainer.step == 1:  # the first step of the new run: a SIGTERM arrives
            os.kill(os.getpid(), signal.SIGTERM)
        return result

    trainer.train_step = step_then_signal
    assert trainer.train() == {"status": "sigterm", "step": 2}
    # the 3-step run.json and model.pt no longer pose as the run's result; the interrupted step is checkpointed
    assert not (out / "run.json").exists() and not (out / "model.pt").exists()
    assert sorted(p.name for p in (out / "checkpoints").iterdir()) == ["step_000002.pt"]
    Trainer(tiny_config(tiny_dataset.root, steps=5), out, device="cpu", progress=False, resume=True).train()
    assert json.loads((out / "run.json").read_text())["steps"] == 5


def test_the_optimizer_follows_the_learning_rate_schedule(tiny_dataset, tmp_path, tiny_config):
    # lr 0.02, warm-up 2 of 4 steps, final ratio 0.1: factor (s + 1) / 2 in the warm-up, then
    # 0.1 + 0.9 (1 + cos(pi (s - 2) / 2)) / 2. Before step s (0-based) Adam uses lr x factor(s)
    cfg = tiny_config(tiny_dataset.root, "train.lr=0.02", "train.lr_final_ratio=0.1", steps=4)
    trainer = Trainer(cfg, tmp_path / "lr", device="cpu", progress=False)
    group = trainer.optimizer.param_groups[0]
    assert group["lr"] == pytest.approx(0.01)
    before = [p.detach().clone() for _, p in trainer._named_params]
    seen = []
    for _ in range(4):
        trainer.train_step()
        trainer.step += 1
        seen.append(group["lr"])
        if trainer.step == 1:
            # Adam's first update is lr x g / (|g| + eps): lr itself wherever |g| >> eps
            moved = max((p.detach() - b).abs().max().item() for (_, p), b in zip(trainer._named_params, before,
                                                                               strict=True))
            assert moved == pytest.approx(0.01, rel=1e-3)
    assert seen == pytest.approx([0.02, 0.02, 0.011, 0.002], rel=1e-9)
    assert [r["lr"] for r in trainer.log_rows] == [] and all(trainer.flush_steps())
    assert [r["lr"] for r in trainer.log_rows] == pytest.approx(seen, rel=1e-9)  # the log: the next step's rate


def test_a_non_finite_gradient_with_finite_terms_skips_the_step(tiny_dataset, tmp_path, tiny_config, capsys):
    trainer = Trainer(tiny_config(tiny_dataset.root), tmp_path / "nan-grad", device="cpu", progress=False)
    name, param = next((n, p) for n, p in trainer._named_params if n.startswith("field."))
    param.register_hook(lambda g: g * float("nan"))
    before = {n: p.detach().clone() for n, p in trainer._named_params}
    pending = trainer.train_step()
    assert torch.isfinite(pending.values).all()  # every loss term is finite
    assert trainer.flush_steps() == [None]
    assert f"non-finite gradient in {name}" in capsys.readouterr().err
    for n, p in trainer._named_params:  # skipped: no parameter moved, the poisoned one included
        assert torch.equal(p.detach(), before[n]), n


class _Drawn(Exception):
    pass


def _first_draw(tiny_dataset, tmp_path, tiny_config, monkeypatch, seed: int,
                batch: int = 64) -> tuple[torch.Tensor, int]:
    """The flat ray indices of a trainer's first step (the step stops once they are drawn) and the ray count."""
    cfg = tiny_config(tiny_dataset.root, f"train.batch_rays={batch}", seed=seed)
    trainer = Trainer(cfg, tmp_path / f"seed{seed}-{batch}", device="cpu", progress=False)
    drawn = []

    def record(flat):
        drawn.append(flat.clone())
        raise _Drawn

    monkeypatch.setattr(trainer.train_rays, "batch", record)
    with pytest.raises(_Drawn):
        trainer.train_step()
    return drawn[0], trainer.train_rays.n_rays


def test_the_seed_sets_the_ray_draws(tiny_dataset, tmp_path, tiny_config, monkeypatch):
    a, _ = _first_draw(tiny_dataset, tmp_path / "a", tiny_config, monkeypatch, 0)
    again, _ = _first_draw(tiny_dataset, tmp_path / "b", tiny_config, monkeypatch, 0)
    other, _ = _first_draw(tiny_dataset, tmp_path / "c", tiny_config, monkeypatch, 1)
    assert torch.equal(a, again)
    assert not torch.equal(a, other)


def test_ray_draws_reach_every_pixel_of_every_frame(tiny_dataset, tmp_path, tiny_config, monkeypatch):
    # 3 training frames of 16 x 12: 576 rays. 16 384 uniform draws with replacement miss a given ray with
    # probability (1 - 1/576)^16384 ~ e^-28, so every ray, the last one included, is drawn
    flat, n_rays = _first_draw(tiny_dataset, tmp_path, tiny_config, monkeypatch, 0, batch=16384)
    assert n_rays == 3 * 16 * 12
    assert torch.equal(torch.unique(flat), torch.arange(n_rays))


def test_a_flat_index_is_frame_row_col_of_one_pixel(tiny_dataset):
    """``RayDataset.batch``: flat = frame * H * W + row * W + col, colour and direction of that same pixel."""
    from stages.model.ray_dataset import RayDataset
    from stages.model.scene_normalization import SceneNormalization

    ds = tiny_dataset
    frames = ds.frames_in("train")
    rays = RayDataset(ds, frames, SceneNormalization.from_dataset(ds), 0.05)
    h, w = 12, 16
    picks = [(0, 2, 5), (1, 11, 0), (2, 7, 15), (1, 0, 9), (2, 10, 3)]  # (frame, row, col), row != col
    flat = torch.tensor([f * h * w + r * w + c for f, r, c in picks])
    batch = rays.batch(flat)
    cam = ds.camera
    for i, (f, r, c) in enumerate(picks):
        image = ds.load_image(frames[f])
        torch.testing.assert_close(batch.rgb[i], torch.tensor(image[r, c], dtype=torch.float32), atol=0.6 / 255,
                                   rtol=0)
        # pixel centre (c + 0.5, r + 0.5) in OpenGL camera axes (x right, y up, z back), rotated to the world;
        # the [-1, 1] scene box is already the normalised frame
        d = np.array([(c + 0.5 - cam.cx) / cam.fx, -(r + 0.5 - cam.cy) / cam.fy, -1.0])
        c2w = np.asarray(frames[f].c2w)
        d = c2w[:3, :3] @ d
        torch.testing.assert_close(batch.rays.directions[i], torch.tensor(d / np.linalg.norm(d), dtype=torch.float32))
        torch.testing.assert_close(batch.rays.origins[i], torch.tensor(c2w[:3, 3], dtype=torch.float32))
