"""The fast paths of issue 16 give the same results as the plain formulations, and a step never syncs."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from random_targets import random_language_targets

from stages.model import Trainer, load_config
from stages.model.config import ModelConfig
from stages.model.methods import LiveSceneModel, SceneInfo
from stages.model.step_counters import count_host_syncs
from stages.model.trainer import compile_fields

ALPHA, DIM = 3, 16


def _model(buckets: int, interpolate_by: str, mode: str = "given") -> LiveSceneModel:
    cfg = ModelConfig()
    cfg.field.base_resolution, cfg.field.channels, cfg.field.scales = 8, 4, [1]
    cfg.proposal.resolutions, cfg.sampling.num_proposal_samples = [[8, 4]], [8]
    cfg.probability.resolution, cfg.language.buckets, cfg.language.interpolate_by = 8, buckets, interpolate_by
    cfg.state.mode = mode
    info = SceneInfo(objects=[f"o{i}" for i in range(ALPHA)], n_frames=10, key_times=[0.0], key_states=[[0.0] * 3],
                     language_dim=DIM, language_levels=buckets)
    return LiveSceneModel(cfg, info)


def _per_sample_reference(model: LiveSceneModel, weights: torch.Tensor, logits: torch.Tensor,
                          states: torch.Tensor, times: torch.Tensor) -> torch.Tensor:
    """Today's formulation before issue 16: look every sample's entry up, then volume-render the rows."""
    r, s = weights.shape
    region = logits.detach().argmax(-1).reshape(-1)
    st = states[:, None, :].expand(r, s, ALPHA).reshape(-1, ALPHA)
    if model.config.language.interpolate_by == "frame":
        value = times[:, None].expand(r, s).reshape(-1)
    else:
        value = torch.gather(st, 1, region.clamp(max=ALPHA - 1)[:, None])[:, 0]
    rows = model.language_table(region, value).view(r, s, DIM)
    return (weights.detach()[..., None] * rows).sum(dim=1)


@pytest.mark.parametrize("mode,interpolate_by", [("given", "kappa"), ("learned", "kappa"), ("given", "frame")])
@pytest.mark.parametrize("buckets", [1, 2, 5])
def test_region_weighted_language_equals_per_sample_lookup(mode, interpolate_by, buckets):
    torch.manual_seed(buckets)
    model = _model(buckets, interpolate_by, mode)
    r, s = 37, 23
    weights = torch.rand(r, s) * (torch.rand(r, s) > 0.2)  # some empty samples
    logits = torch.randn(r, s, ALPHA + 1) * 3
    states = torch.rand(r, ALPHA)
    states[0], states[1] = 0.0, 1.0  # exact bucket edges
    if mode == "learned":  # states come out of a network: they carry a gradient the language loss must not touch
        states = (states * 2 - 1).requires_grad_(True)
        states_in = torch.sigmoid(states * 4)
    else:
        states_in = states
    times = torch.rand(r)
    upstream = torch.randn(r, DIM)

    fast = model.render_language(weights, logits, states_in, times)
    (fast * upstream).sum().backward()
    fast_grads = [p.grad.clone() for p in model.language_table.parameters()]
    model.zero_grad()
    ref = _per_sample_reference(model, weights, logits, states_in, times)
    (ref * upstream).sum().backward()

    torch.testing.assert_close(fast, ref, rtol=1e-5, atol=1e-5)
    for got, want in zip(fast_grads, (p.grad for p in model.language_table.parameters()), strict=True):
        torch.testing.assert_close(got, want, rtol=1e-4, atol=1e-5)
    if mode == "learned":
        assert states.grad is None  # neither formulation sends a gradient into the states


@pytest.mark.parametrize("extra", [[], ["model.state.mode=learned"], ["train.camera_opt=SO3xR3"]])
def test_training_steps_between_log_intervals_make_no_host_sync(tiny_dataset, tmp_path, tiny_config, extra):
    targets = random_language_targets(tmp_path / "targets.npz", tiny_dataset.objects, DIM)
    cfg = tiny_config(tiny_dataset.root, *extra, steps=20)
    cfg.language_targets = str(targets)
    trainer = Trainer(cfg, tmp_path / "run", device="cpu", progress=False)
    assert trainer.model.language_table is not None
    for _ in range(2):  # first steps allocate optimiser state
        trainer.train_step()
        trainer.step += 1
    trainer.flush_steps()
    with count_host_syncs() as syncs:
        for _ in range(3):
            trainer.train_step()
            trainer.step += 1
    assert dict(syncs) == {}
    results = trainer.flush_steps()
    assert len(results) == 3 and all(r is not None and np.isfinite(r["loss"]) for r in results)
    assert "language" in results[0]


def test_sync_counter_sees_the_calls_it_patches():
    with count_host_syncs() as syncs:
        t = torch.ones(2)
        bool(t[0])
        float(t[1])
        t.tolist()
        t.sum().item()
    assert syncs == {"__bool__": 1, "__float__": 1, "tolist": 1, "item": 1}


def test_skipped_step_is_named_when_the_queue_is_read(tiny_dataset, tmp_path, tiny_config, capsys):
    trainer = Trainer(tiny_config(tiny_dataset.root, steps=10), tmp_path / "run", device="cpu", progress=False)
    before = {k: v.clone() for k, v in trainer.model.state_dict().items()}
    real = trainer.model.loss_dict

    def poisoned(*args, **kwargs):
        terms = real(*args, **kwargs)
        terms["distortion"] = terms["distortion"] * float("nan")
        return terms

    trainer.model.loss_dict = poisoned
    trainer.train_step()
    assert capsys.readouterr().err == ""  # nothing is known until the queue is read
    assert trainer.flush_steps() == [None]
    assert "step 0: skipped (non-finite loss term(s) ['distortion'])" in capsys.readouterr().err
    for k, v in trainer.model.state_dict().items():  # the device-side skip left every weight as it was
        torch.testing.assert_close(v, before[k], rtol=0, atol=0, equal_nan=True, msg=k)
    assert all(float(s["step"]) == 0 for s in trainer.optimizer.state.values())


@pytest.mark.parametrize("method", ["livescene", "mk-planes", "conerf"])
def test_fields_compile_without_graph_breaks(tiny_dataset, method):
    cfg = load_config("cpu-demo", ["model.field.base_resolution=8", "model.field.scales=[1]"], method=method)
    info = SceneInfo(objects=["a", "b"], n_frames=4)
    from stages.model.methods import build_model

    model = build_model(method, cfg.model, info)
    n = 64
    pos = torch.rand(n, 3) * 2 - 1
    coords = torch.cat([pos, torch.rand(n, model.n_dims - 3) * 2 - 1], dim=1)
    dirs = torch.nn.functional.normalize(torch.randn(n, 3), dim=-1)
    calls = [(model.field, (coords, dirs, {})), (model.probability_field, (pos, torch.rand(n, 2), {})),
             (model.proposal_fields[0], (coords, {}))]
    for module, args in calls:
        explained = torch._dynamo.explain(module)(*args)
        assert explained.graph_break_count == 0, (type(module).__name__, explained.break_reasons)
        with torch.no_grad():  # the no-grad calls of a step and of the evaluation (the CPU's bag-of-rows path)
            explained = torch._dynamo.explain(module)(*args)
        assert explained.graph_break_count == 0, (type(module).__name__, "no grad", explained.break_reasons)
    compile_fields(model)  # in place: the state_dict keeps its keys
    assert all(not k.startswith("_orig_mod") and "._orig_mod" not in k for k in model.state_dict())


def test_render_fast_path_matches_full_render_within_its_bound(trained_run, monkeypatch):
    from stages.model import load_run
    from stages.model.methods import livescene

    run = load_run(trained_run)
    cam_origins = np.tile(np.array([[0.0, 0.0, 0.0]]), (200, 1))
    dirs = np.random.default_rng(0).normal(size=(200, 3))
    state = np.full(len(run.objects), 0.5)
    fast = run.render_rays(cam_origins, dirs, state, outputs=("rgb",))
    assert set(fast) == {"rgb"}
    bound = run.config.model.sampling.num_samples * livescene.RENDER_WEIGHT_FLOOR
    monkeypatch.setattr(livescene, "RENDER_WEIGHT_FLOOR", -1.0)  # every sample gets its colour
    full = run.render_rays(cam_origins, dirs, state)
    assert {"rgb", "depth", "accumulation", "probs"} <= set(full)
    assert np.abs(fast["rgb"] - full["rgb"]).max() <= bound + 1e-6


@pytest.mark.parametrize("training", [True, False])
def test_each_sample_is_coloured_at_its_own_rays_direction(monkeypatch, training):
    """Directions are encoded once per ray; every sample must still get its own ray's encoding (both paths)."""
    from stages.model.methods import livescene
    from stages.model.ray_samplers import uniform_samples
    from stages.model.rays import RayBundle

    torch.manual_seed(0)
    model = _model(2, "kappa").train(training)
    r, s = 29, 7
    dirs = torch.nn.functional.normalize(torch.randn(r, 3), dim=-1)
    rays = RayBundle(torch.zeros(r, 3), dirs, torch.full((r,), 0.1), torch.full((r,), 1.5), torch.rand(r, ALPHA))
    samples = uniform_samples(rays.nears, rays.fars, s, False, False, None)
    seen: list[torch.Tensor] = []
    colour = model.field.color
    monkeypatch.setattr(model.field, "color", lambda geo, enc: seen.append(enc) or colour(geo, enc))
    monkeypatch.setattr(livescene, "RENDER_WEIGHT_FLOOR", -1.0)  # the render path colours every sample too
    with torch.no_grad():
        out = model._level(rays, samples, rays.states, 0, final=True, grad_density=False)
    assert out["rgb"].shape == (r, s, 3)
    assert torch.equal(seen[0], model.field.direction_encoding(dirs.repeat_interleave(s, dim=0)))


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device (CI has none)")
def test_cuda_training_steps_pass_sync_debug_mode_error(tiny_dataset, tmp_path, tiny_config):
    targets = random_language_targets(tmp_path / "targets.npz", tiny_dataset.objects, DIM)
    # eager steps (a graph's capture syncs once; test_step_graphs.py checks its replays)
    cfg = tiny_config(tiny_dataset.root, "train.log_every=1000", "train.cuda_graphs=false", steps=40)
    cfg.language_targets = str(targets)
    trainer = Trainer(cfg, tmp_path / "run", device="cuda", progress=False)
    for _ in range(2):
        trainer.train_step()
        trainer.step += 1
    trainer.flush_steps()
    torch.cuda.synchronize()
    torch.cuda.set_sync_debug_mode("error")
    try:
        for _ in range(20):
            trainer.train_step()
            trainer.step += 1
    finally:
        torch.cuda.set_sync_debug_mode("default")
    assert all(r is not None for r in trainer.flush_steps())
