"""Baselines on the shared harness: plane counts, parameter growth, gating, training, rendering, the comparison."""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest
import torch

from stages.compare.cli import main as compare_main
from stages.compare.method_comparison import (
    ALL_METHODS,
    CompareConfig,
    compare_methods,
    params_vs_objects,
)
from stages.model import Trainer, build_model, load_config, load_run
from stages.model.fields import ProbabilityField
from stages.model.methods import SceneInfo
from stages.model.methods.mk_planes import mk_planes_pairs, mk_planes_star_pairs
from stages.model.ray_dataset import RayBatch
from stages.model.rays import RayBundle


def _info(n_objects: int) -> SceneInfo:
    return SceneInfo(objects=[f"o{i}" for i in range(n_objects)], n_frames=6)


def _tiny_model_config(tiny_overrides):
    return load_config("cpu-demo", [*tiny_overrides, "model.field.scales=[1,2]"]).model


@pytest.mark.parametrize("a", [1, 2, 5])
def test_plane_counts_per_scale(a, tiny_overrides):
    cfg = _tiny_model_config(tiny_overrides)
    mk = build_model("mk-planes", cfg, _info(a))
    star = build_model("mk-planes-star", cfg, _info(a))
    assert len(mk.field.encoding.grids) == 2
    for grid in mk.field.encoding.grids:
        assert len(grid.planes) == math.comb(3 + a, 2)
        assert grid.n_dims == 3 + a
    for grid in star.field.encoding.grids:
        assert len(grid.planes) == 3 + 3 * a
    # the proposal grids factorise the same space
    assert len(mk.proposal_fields[0].encoding.planes) == math.comb(3 + a, 2)
    assert len(star.proposal_fields[0].encoding.planes) == 3 + 3 * a
    # LiveScene stays at the six planes of (x, y, z, k)
    live = build_model("livescene", cfg, _info(a))
    assert [len(g.planes) for g in live.field.encoding.grids] == [6, 6]


def test_star_pairs_couple_no_two_states():
    assert mk_planes_star_pairs(2) == [(0, 1), (0, 2), (1, 2), (0, 3), (1, 3), (2, 3), (0, 4), (1, 4), (2, 4)]
    assert all(a < 3 for a, _ in mk_planes_star_pairs(5))
    assert (3, 4) in mk_planes_pairs(2)


def test_livescene_parameters_do_not_grow_with_objects(tiny_overrides):
    cfg = _tiny_model_config(tiny_overrides)

    def count(method: str, a: int) -> tuple[int, int]:
        m = build_model(method, cfg, _info(a))
        dec = m.probability_field.decoder
        io_layers = sum(p.numel() for layer in (dec[0], dec[-1]) for p in layer.parameters())
        total = sum(p.numel() for p in m.parameters())
        return total - io_layers, sum(p.numel() for p in m.field.parameters())

    live = [count("livescene", a) for a in (1, 2, 5)]
    assert live[0] == live[1] == live[2]
    mk = [count("mk-planes", a)[1] for a in (1, 2, 5)]
    star = [count("mk-planes-star", a)[1] for a in (1, 2, 5)]
    assert mk[0] < mk[1] < mk[2] and star[0] < star[1] < star[2]
    assert mk[2] > star[2]  # quadratic versus linear growth


def test_conerf_gates_attributes_by_mask(tiny_overrides):
    model = build_model("conerf", _tiny_model_config(tiny_overrides), _info(2))
    states = torch.tensor([[0.9, 0.2], [0.9, 0.2], [0.9, 0.2]])
    logits = torch.tensor([[20.0, 0.0, 0.0], [0.0, 20.0, 0.0], [0.0, 0.0, 20.0]])  # object 0, object 1, background
    gated = model.gated_attributes(logits, states)
    assert torch.allclose(gated[0], torch.tensor([0.8, 0.0]), atol=1e-6)
    assert torch.allclose(gated[1], torch.tensor([0.0, -0.6]), atol=1e-6)
    assert torch.allclose(gated[2], torch.zeros(2), atol=1e-6)
    # the gate is differentiable, so the photometric loss reaches the mask head as in CoNeRF
    logits.requires_grad_(True)
    model.gated_attributes(logits, states).sum().backward()
    assert logits.grad is not None and float(logits.grad.abs().sum()) > 0


def test_k_planes_reads_time_not_states(tiny_overrides):
    model = build_model("k-planes", _tiny_model_config(tiny_overrides), _info(2))
    pos = torch.zeros(4, 3)
    logits = torch.zeros(4, 3)
    t = torch.tensor([0.0, 0.25, 0.5, 1.0])
    a = model.coordinates(pos, torch.zeros(4, 2), logits, t)
    b = model.coordinates(pos, torch.ones(4, 2), logits, t)
    assert torch.equal(a, b)
    assert torch.allclose(a[:, 3], 2 * t - 1)


def _rays(n: int, n_objects: int) -> RayBundle:
    g = torch.Generator().manual_seed(3)
    d = torch.nn.functional.normalize(torch.randn(n, 3, generator=g), dim=-1)
    return RayBundle(torch.zeros(n, 3), d, torch.full((n,), 0.05), torch.full((n,), 1.5),
                     torch.rand(n, n_objects, generator=g), torch.rand(n, generator=g))


@pytest.mark.parametrize(("method", "reads"), [("livescene", True), ("conerf", True), ("mk-planes", False),
                                               ("mk-planes-star", False), ("k-planes", False)])
def test_probability_field_runs_at_every_level_only_where_the_field_reads_it(method, reads, tiny_overrides,
                                                                             monkeypatch):
    model = build_model(method, _tiny_model_config(tiny_overrides), _info(2)).train()
    assert model.field_reads_probabilities is reads
    calls = []
    forward = type(model.probability_field).forward
    monkeypatch.setattr(type(model.probability_field), "forward",
                        lambda self, *a, **k: calls.append(1) or forward(self, *a, **k))
    rays = _rays(16, 2)
    out = model(rays, step=300, generator=torch.Generator().manual_seed(0))
    levels = len(model.proposal_fields) + 1
    assert len(calls) == (levels if reads else 1)
    # the mask losses supervise every level whose logits exist (all for LiveScene and CoNeRF, the final one
    # otherwise), unless ``mask_levels`` keeps them to the final level
    every = reads and model.config.losses.mask_levels == "all"
    assert len(out["level_logits"]) == (levels if every else 1)
    assert set(model.loss_dict(out, RayBatch(rays, torch.rand(16, 3), torch.zeros(16, dtype=torch.long),
                                               torch.zeros(16, dtype=torch.long)), 300)) >= {
        "rgb", "focal_mask"}
    if not reads:
        # the field ignores the logits, so skipping them at the proposal levels changes no rendered pixel
        model.field_reads_probabilities = True
        full = model(rays, step=300, generator=torch.Generator().manual_seed(0))
        assert torch.equal(out["rgb"], full["rgb"]) and torch.equal(out["logits"], full["logits"])


@pytest.mark.parametrize("form", ["logits", "both", "samples"])
def test_mask_levels_final_supervises_the_final_level_and_renders_the_same(form, tiny_overrides, monkeypatch):
    """``losses.mask_levels: final``: the proposal levels still place k by the argmax, from logits computed
    without a graph, and only the final level's logits reach the mask losses; every rendered value is unchanged."""
    forward = ProbabilityField.forward

    def run(levels):
        cfg = load_config("cpu-demo", [*tiny_overrides, "model.field.scales=[1,2]",
                                       f"model.losses.mask_levels={levels}", f"model.losses.focal_mask_on={form}"])
        torch.manual_seed(0)
        model = build_model("livescene", cfg.model, _info(2)).train()
        logits = []
        monkeypatch.setattr(ProbabilityField, "forward",
                            lambda self, *a, **k: logits.append(forward(self, *a, **k)) or logits[-1])
        out = model(_rays(16, 2), step=300, generator=torch.Generator().manual_seed(0))
        return model, out, logits

    _, every, every_logits = run("all")
    model, final, final_logits = run("final")
    levels = len(model.proposal_fields) + 1
    assert len(final_logits) == len(every_logits) == levels  # the k-projection still reads every level
    assert [lg.requires_grad for lg in final_logits] == [False] * (levels - 1) + [True]
    assert all(lg.requires_grad for lg in every_logits)
    for key in ("rgb", "logits", "depth"):
        assert torch.equal(every[key], final[key])
    for key in ("level_logits", "level_probs", "level_samples"):
        if key in every:
            assert len(every[key]) == levels and len(final[key]) == 1
    labels = torch.randint(0, 3, (16,), generator=torch.Generator().manual_seed(1))
    terms = model.loss_dict(final, RayBatch(_rays(16, 2), torch.rand(16, 3), labels, torch.zeros(16, dtype=torch.long)),
                            300)
    (terms["focal_mask"] + terms["repulsion"]).backward()
    assert model.probability_field.decoder[-1].weight.grad.abs().sum() > 0


@pytest.mark.parametrize(("mode", "key"), [("probabilities", "level_probs"), ("samples", "level_samples")])
def test_focal_mask_forms_supervise_every_level(mode, key, tiny_overrides, monkeypatch):
    """``losses.focal_mask_on`` other than logits: every level feeds that form, and ``probs`` is what it trains."""
    cfg = load_config("cpu-demo", [*tiny_overrides, "model.field.scales=[1,2]", "model.losses.mask_levels=all",
                                   f"model.losses.focal_mask_on={mode}"]).model
    model = build_model("livescene", cfg, _info(2)).train()
    rays = _rays(16, 2)
    out = model(rays, step=300, generator=torch.Generator().manual_seed(0))
    assert len(out[key]) == len(out["level_logits"]) == len(model.proposal_fields) + 1
    # weights times probabilities: at most the ray's weight per class, summing to it
    assert out["probs"].shape == (16, 3) and (out["probs"] >= 0).all() and (out["probs"].sum(-1) <= 1 + 1e-5).all()
    labels = torch.randint(0, 3, (16,), generator=torch.Generator().manual_seed(1))
    batch = RayBatch(rays, torch.rand(16, 3), labels, torch.zeros(16, dtype=torch.long))
    monkeypatch.setattr("stages.model.losses.focal_mask_loss",
                        lambda *a, **k: pytest.fail("the logits form must not run"))
    terms = model.loss_dict(out, batch, 300)
    assert torch.isfinite(terms["focal_mask"]) and terms["focal_mask"].item() > 0
    terms["focal_mask"].backward()
    assert model.probability_field.decoder[-1].weight.grad.abs().sum() > 0


def test_focal_mask_both_sums_the_forms_and_keeps_logit_relevancy(tiny_overrides):
    """``focal_mask_on: both``: the probabilities form plus the reference's, relevancy from the rendered logits."""
    def run(mode):
        cfg = load_config("cpu-demo", [*tiny_overrides, "model.field.scales=[1,2]",
                                       f"model.losses.focal_mask_on={mode}"]).model
        torch.manual_seed(0)
        model = build_model("livescene", cfg, _info(2)).train()
        rays = _rays(16, 2)
        out = model(rays, step=300, generator=torch.Generator().manual_seed(0))
        labels = torch.randint(0, 3, (16,), generator=torch.Generator().manual_seed(1))
        batch = RayBatch(rays, torch.rand(16, 3), labels, torch.zeros(16, dtype=torch.long))
        return out, model.loss_dict(out, batch, 300)["focal_mask"]

    (both, loss_both), (_, loss_logits), (_, loss_probs) = run("both"), run("logits"), run("probabilities")
    assert "probs" not in both and len(both["level_probs"]) == len(both["level_logits"])
    assert loss_both.item() == pytest.approx(loss_logits.item() + loss_probs.item(), rel=1e-5)


@pytest.mark.parametrize("method", ["mk-planes", "mk-planes-star", "conerf", "k-planes"])
def test_method_trains_and_renders(method, tiny_dataset, tiny_config, tmp_path):
    out = tmp_path / method
    config = tiny_config(tiny_dataset.root, f"method={method}", steps=3)
    summary = Trainer(config, out, device="cpu", progress=False).train()
    assert summary["method"] == method and summary["steps"] == 3
    assert summary["params"]["total"] > 0 and summary["peak_memory_mib"] > 0
    log = pd.read_csv(out / "train_log.csv")
    assert len(log) == 3 and np.isfinite(log["loss"]).all()
    run = load_run(out)
    frame = tiny_dataset.frames[1]
    img = run.render(tiny_dataset.camera, frame.c2w, frame.state, frame_index=1)
    h, w = tiny_dataset.camera.height, tiny_dataset.camera.width
    assert img["rgb"].shape == (h, w, 3) and np.isfinite(img["rgb"]).all()
    assert img["probs"].shape == (h, w, 4)


def test_conerf_learned_states_use_frame_latents(tiny_dataset, tiny_config, tmp_path):
    config = tiny_config(tiny_dataset.root, "method=conerf", "model.state.mode=learned", steps=3)
    trainer = Trainer(config, tmp_path / "run", device="cpu", progress=False)
    assert type(trainer.model.state_field).__name__ == "FrameLatentStates"
    assert trainer.model.state_field.latents.num_embeddings == len(tiny_dataset.frames)
    trainer.train()
    log = pd.read_csv(tmp_path / "run" / "train_log.csv")
    assert (log["state_mse"] > 0).all()  # key frames supervise the regressed attributes
    states = load_run(tmp_path / "run").learned_states()
    assert states.shape == (len(tiny_dataset.frames), 3) and ((states > 0) & (states < 1)).all()


def test_params_vs_objects_table():
    table = params_vs_objects(ALL_METHODS, range(1, 4), "cpu-demo")
    assert len(table) == 5 * 3
    mk = table[table.method == "mk-planes"].set_index("objects")
    assert mk.loc[3, "planes_per_scale"] == math.comb(6, 2)
    star = table[table.method == "mk-planes-star"].set_index("objects")
    assert star.loc[3, "planes_per_scale"] == 12
    live = table[table.method == "livescene"].set_index("objects")
    assert live["field_params"].nunique() == 1


def test_compare_budget_then_replay_reproduces(tiny_dataset, tiny_overrides, tmp_path, capsys):
    extra = [*tiny_overrides, "train.threads=1"]
    cfg = CompareConfig(data=str(tiny_dataset.root), out=str(tmp_path / "a"), methods=["k-planes"], budget_s=1.0,
                        max_steps=40, overrides=extra, eval_frames=1, isolate=False)
    table = compare_methods(cfg, progress=False)
    row = table.iloc[0]
    assert row["status"] in ("time_budget", "completed"), row["status"]
    assert row["train_seconds"] > 0 and row["steps"] >= 1
    assert np.isfinite(row["psnr"]) and 0 < row["ssim"] <= 1
    written = pd.read_csv(tmp_path / "a" / "compare.csv")
    assert list(written["method"]) == ["k-planes"]
    assert (tmp_path / "a" / "k-planes" / "train_log.csv").is_file()
    fractions = json.loads((tmp_path / "a" / "k-planes" / "time_fractions.json").read_text())
    assert len(fractions) == row["steps"] and fractions == sorted(fractions)
    rc = compare_main(["--data", str(tiny_dataset.root), "--out", str(tmp_path / "b"), "--methods", "k-planes",
                       "--max-steps", "40", "--eval-frames", "1", "--replay", str(tmp_path / "a"), "--in-process",
                       *[x for o in extra for x in ("--set", o)]])
    assert rc == 0
    assert "k-planes" in capsys.readouterr().out
    again = json.loads((tmp_path / "b" / "compare.json").read_text())["methods"][0]
    assert again["steps"] == row["steps"]
    first = pd.read_csv(tmp_path / "a" / "k-planes" / "train_log.csv")
    second = pd.read_csv(tmp_path / "b" / "k-planes" / "train_log.csv")
    assert np.array_equal(first["loss"].to_numpy(), second["loss"].to_numpy())
    assert again["psnr"] == row["psnr"]


def test_replay_needs_a_recorded_schedule(tiny_dataset, tmp_path, capsys):
    rc = compare_main(["--data", str(tiny_dataset.root), "--out", str(tmp_path / "b"), "--methods", "k-planes",
                       "--replay", str(tmp_path / "nothing"), "--in-process"])
    assert rc == 2
    assert "time_fractions.json" in capsys.readouterr().err


def test_compare_refuses_unknown_dataset(tmp_path, capsys):
    assert compare_main(["--data", str(tmp_path / "missing"), "--out", str(tmp_path / "o")]) == 2
    assert "error:" in capsys.readouterr().err
