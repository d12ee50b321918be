"""Per-frame colour correction of the training images (`model.appearance.mode: affine`, docs/model.md "Exposure")."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from stages.model import Trainer, build_model, load_config, load_run
from stages.model.methods import SceneInfo
from stages.model.ray_dataset import RayBatch
from stages.model.rays import RayBundle
from stages.scene import InputError
from tests.pan_frames import write_pan_dataset

INFO = SceneInfo(objects=["o0", "o1"], n_frames=6)


def _rays(n: int) -> RayBundle:
    g = torch.Generator().manual_seed(3)
    d = torch.nn.functional.normalize(torch.randn(n, 3, generator=g), dim=-1)
    return RayBundle(torch.zeros(n, 3), d, torch.full((n,), 0.05), torch.full((n,), 1.5),
                     torch.rand(n, 2, generator=g), torch.rand(n, generator=g))


def _model(tiny_overrides, mode: str, method: str = "livescene"):
    cfg = load_config("cpu-demo", [*tiny_overrides, "model.field.scales=[1,2]", f"model.appearance.mode={mode}"])
    torch.manual_seed(0)
    return build_model(method, cfg.model, INFO).train()


def test_the_reference_has_no_correction(tiny_overrides):
    model = _model(tiny_overrides, "none")
    assert model.appearance is None and not any("appearance" in k for k in model.state_dict())
    rgb = torch.rand(4, 3)
    assert model.frame_colour(rgb, torch.tensor([0, 1, 2, 3])) is rgb


@pytest.mark.parametrize("method", ["livescene", "mk-planes", "conerf"])
def test_the_photometric_loss_sees_each_frame_through_its_gain_and_bias(tiny_overrides, method):
    model = _model(tiny_overrides, "affine", method)
    assert model.appearance.shape == (6, 6) and not model.appearance.any()  # identity at the start
    with torch.no_grad():
        model.appearance[2] = torch.tensor([0.2, -0.1, 0.0, 0.02, 0.0, -0.03])
    rays = _rays(16)
    out = model(rays, step=300, generator=torch.Generator().manual_seed(0))
    frames = torch.tensor([2] * 8 + [4] * 8)
    target = torch.rand(16, 3, generator=torch.Generator().manual_seed(1))
    terms = model.loss_dict(out, RayBatch(rays, target, torch.zeros(16, dtype=torch.long), frames), 300)
    # the corrections are centred over the training frames (here all six): frame 2 keeps 5/6 of its own
    a = model.frame_corrections().detach()
    torch.testing.assert_close(a[2], torch.tensor([0.2, -0.1, 0.0, 0.02, 0.0, -0.03]) * 5 / 6)
    torch.testing.assert_close(a.mean(0), torch.zeros(6), atol=1e-7, rtol=0)
    seen = out["rgb"].detach() * torch.exp(a[frames, :3]) + a[frames, 3:]
    w = model.config.losses
    assert terms["rgb"].item() == pytest.approx(w.rgb * torch.mean((seen - target) ** 2).item(), rel=1e-5)
    assert terms["appearance"].item() == pytest.approx(w.appearance * a[frames].square().mean().item(), rel=1e-6)


def test_only_training_frames_set_the_centre(tiny_overrides):
    cfg = load_config("cpu-demo", [*tiny_overrides, "model.field.scales=[1,2]", "model.appearance.mode=affine"])
    model = build_model("livescene", cfg.model, SceneInfo(objects=["o0"], n_frames=4, train_frames=[0, 2])).train()
    with torch.no_grad():
        model.appearance[:] = torch.arange(4.0).unsqueeze(-1).expand(4, 6)
    a = model.frame_corrections()
    assert a[[0, 2]].sum(0).abs().max() == 0 and (a[1] == 0).all() and (a[3] == 2).all()  # centre 1 = mean(0, 2)
    (a[0] + 3.0 * a[1]).sum().backward()  # held-out rows take no part in the centre: only their own use reaches them
    grad = model.appearance.grad
    assert grad[[0, 2]].abs().gt(0).all() and (grad[1] == 3.0).all() and not grad[3].any()


def test_renders_use_the_nominal_colour(tiny_dataset, tmp_path, tiny_config):
    """A trained run renders the same image whatever its frames' corrections: evaluation sees nominal colour."""
    out = tmp_path / "run"
    Trainer(tiny_config(tiny_dataset.root, "model.appearance.mode=affine", steps=3), out, device="cpu",
            progress=False).train()
    run = load_run(out)
    assert run.model.appearance is not None and run.model.appearance.shape[0] == len(tiny_dataset.frames)
    frame = tiny_dataset.frames[0]
    before = run.render(tiny_dataset.camera, frame.c2w, frame.state)["rgb"]
    with torch.no_grad():
        run.model.appearance.fill_(0.5)
    assert (run.render(tiny_dataset.camera, frame.c2w, frame.state)["rgb"] == before).all()


@pytest.mark.parametrize("sigma, chosen", [(0.05, "measured"), (0.0, "none")])
def test_auto_corrects_the_exposure_only_where_it_varies(tmp_path, tiny_config, sigma, chosen):
    """``auto`` measures the frames before the model is built; the run records the choice, and a resumed run
    measures the same and continues (the checkpoint's config holds the resolved mode)."""
    gains = np.random.default_rng(4).normal(0.0, sigma, (8, 3))
    ds = write_pan_dataset(tmp_path / "ds", gains)
    out = tmp_path / "run"
    Trainer(tiny_config(ds.root, "model.appearance.mode=auto", steps=2), out, device="cpu", progress=False).train()
    recorded = json.loads((out / "run.json").read_text())["appearance"]
    assert recorded["requested"] == "auto" and recorded["mode"] == chosen and recorded["tied_frames"] == 8
    assert recorded["spread"] == pytest.approx(float((gains - gains.mean(0)).std(0).mean()), abs=0.004)
    assert load_run(out).model.appearance is None  # nothing learned either way
    assert (load_run(out).exposure_gains is not None) == (chosen == "measured")
    assert "log_gains" not in recorded and ("reason" in recorded) and recorded["auto_spread"] == 0.01
    assert list((out / "checkpoints").glob("step_*.pt"))  # what the resume below continues from
    # the same run again: its checkpoint is not stale (its config holds the resolved mode), nothing left to train
    Trainer(tiny_config(ds.root, "model.appearance.mode=auto", steps=2), out, device="cpu", progress=False,
            resume=True).train()
    assert json.loads((out / "run.json").read_text())["appearance"] == recorded


def test_a_set_mode_is_recorded_without_measuring(trained_run):
    assert json.loads((trained_run / "run.json").read_text())["appearance"] == {"mode": "none"}


def test_measured_gains_are_divided_out_of_the_training_images(tmp_path, tiny_config):
    """``measured``: nothing is learned; the training colours are those of the capture at one exposure."""
    gains = np.random.default_rng(6).normal(0.0, 0.08, (8, 3))
    jittered = write_pan_dataset(tmp_path / "jittered", gains - gains.mean(0))
    plain = write_pan_dataset(tmp_path / "plain", np.zeros((8, 3)))
    trainers = {ds.root.name: Trainer(tiny_config(ds.root, "model.appearance.mode=measured", steps=1),
                                      tmp_path / f"run-{ds.root.name}", device="cpu", progress=False)
                for ds in (jittered, plain)}
    a, b = (trainers[n].train_rays.images.int() for n in ("jittered", "plain"))
    raw = Trainer(tiny_config(jittered.root, steps=1), tmp_path / "raw", device="cpu", progress=False)
    assert (raw.train_rays.images.int() - b).abs().float().mean() > 5  # the jitter, as trained without a correction
    assert (a - b).abs().float().mean() < 1.0 and (a - b).abs().max() <= 6
    trainers["jittered"].train()
    recorded = json.loads((tmp_path / "run-jittered" / "run.json").read_text())["appearance"]
    assert recorded["mode"] == "measured" and recorded["tied_frames"] == 8 and "log_gains" not in recorded
    loaded = load_run(tmp_path / "run-jittered")
    assert loaded.model.appearance is None
    # every frame's gains, held-out ones too, for the evaluation's PSNR at the nominal exposure
    assert sorted(loaded.exposure_gains) == sorted(f.frame_id for f in jittered.frames)
    np.testing.assert_allclose([loaded.exposure_gains[f.frame_id] for f in jittered.frames], gains - gains.mean(0),
                               atol=0.01)


def test_a_saved_estimate_trains_as_the_trainer_s_own_measurement(tmp_path, tiny_config):
    """``--exposure`` (the workflow measures once per scene): the same gains, so the same training images bit for
    bit and the same choice; a mode that measures nothing does not read the file."""
    from stages.scene.cli import main as scene_main

    ds = write_pan_dataset(tmp_path / "ds", np.random.default_rng(11).normal(0.0, 0.05, (8, 3)))
    saved = tmp_path / "exposure.json"
    assert scene_main(["exposure", str(ds.root), "--out", str(saved)]) == 0
    own = Trainer(tiny_config(ds.root, "model.appearance.mode=auto", steps=1), tmp_path / "own", device="cpu",
                  progress=False)
    cfg = tiny_config(ds.root, "model.appearance.mode=auto", steps=1)
    cfg.exposure = str(saved)
    read = Trainer(cfg, tmp_path / "read", device="cpu", progress=False)
    assert own.appearance["mode"] == read.appearance["mode"] == "measured"
    assert read.appearance["measured_by"] == "exposure file" and own.appearance["measured_by"] == "trainer"
    assert own.appearance["spread"] == read.appearance["spread"]
    assert torch.equal(own.train_rays.images, read.train_rays.images) and own.data_digest == read.data_digest
    cfg = tiny_config(ds.root, steps=1)
    cfg.exposure = str(tmp_path / "absent.json")  # not read: mode none
    assert Trainer(cfg, tmp_path / "none", device="cpu", progress=False).appearance == {"mode": "none"}


def test_measured_mode_refuses_frames_it_cannot_measure(tiny_dataset, tmp_path, tiny_config):
    """Random images (no frame overlaps another): ``measured`` names the data and the fix; ``auto`` keeps them."""
    refused = r"transforms.json: .*cannot be measured.*fix: set model\.appearance\.mode=affine"
    with pytest.raises(InputError, match=refused):
        Trainer(tiny_config(tiny_dataset.root, "model.appearance.mode=measured"), tmp_path / "m", device="cpu",
                progress=False)
    t = Trainer(tiny_config(tiny_dataset.root, "model.appearance.mode=auto"), tmp_path / "a", device="cpu",
                progress=False)
    assert t.appearance["mode"] == "none" and t.appearance["spread"] is None


@pytest.mark.parametrize("mode", ["fixed", "last_sample"])
@pytest.mark.parametrize("training", [True, False])
def test_what_a_ray_does_not_cover_shows_the_background(tiny_overrides, mode, training):
    """``last_sample``: the colour of each ray's last sample shows behind it (nerfacto's default), in training and
    in the render path, which therefore colours that sample even when its weight is under the floor; ``fixed``:
    the reference's white (docs/model.md, "Background colour"). An opaque wall at x > 0.3 hides the last sample of
    the rays that reach it (weight under RENDER_WEIGHT_FLOOR); the rays that point away stay half transparent."""
    from stages.model.methods.livescene import RENDER_WEIGHT_FLOOR

    cfg = load_config("cpu-demo", [*tiny_overrides, f"model.sampling.background_mode={mode}"])
    torch.manual_seed(0)
    model = build_model("livescene", cfg.model, INFO).train(training)
    density = model.field.density

    def walled(coords, cache=None):
        sigma, geo = density(coords, cache)
        return torch.where(coords[:, 0] > 0.3, torch.full_like(sigma, 1e4), sigma), geo

    model.field.density = walled
    final: dict = {}
    level = model._level

    def spy(*args, **kwargs):
        out = level(*args, **kwargs)
        if kwargs.get("final"):
            final.update(out)
        return out

    model._level = spy
    with torch.set_grad_enabled(training):
        out = model(_rays(64), outputs=("rgb",)) if not training else model(_rays(64))
    w, rgb = final["weights"].detach(), final["rgb"].detach()
    behind = rgb[:, -1, :] if mode == "last_sample" else torch.ones(3)
    hidden = w[:, -1] <= RENDER_WEIGHT_FLOOR
    assert hidden.sum() >= 8  # rays whose last sample the render path would otherwise leave uncoloured
    if mode == "last_sample":
        assert (rgb[:, -1, :] > 0).all()  # computed for every ray, visible or not
        assert (rgb[hidden, -1, :] > 0).all()
    expected = (w[..., None] * rgb).sum(1) + (1.0 - w.sum(-1, keepdim=True)) * behind
    torch.testing.assert_close(out["rgb"].detach(), expected)
    assert (1.0 - w.sum(-1)).max() > 0.05  # the check sees the background: some rays are far from opaque
