"""Numerical stability checks (group ``numerics``): stiff and extreme inputs must train and render finitely.

Each check trains a tiny LiveScene briefly (or probes one component) and checks
finite losses, gradients and renders AND a useful result: the loss goes down,
the weights stay a distribution, the reduced-precision render stays close to
float32, a scene in other units trains like the same scene in metres. A check's
docstring is the ``checks`` text of its row in the summary (docs/stability.md).
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import warnings
from pathlib import Path
from unittest import mock

import numpy as np
import pytest
import torch
import yaml

from stages.model.config import ModelConfig
from stages.model.fields import ProbabilityField, RadianceField
from stages.model.fields.activations import trunc_exp
from stages.model.methods import livescene
from stages.model.rays import RayBundle
from stages.model.renderers import render_weights
from stages.model.scene_normalization import aabb_near_far
from stages.scene import read_scene, write_scene
from stages.stability.collector import Outcome

from .brief_training import BriefRun, make_trainer, nonfinite_grads, render_held_out, require_learning, train_briefly
from .case_context import CaseContext
from .tiny_scenes import band_labels, capture_dataset, hand_built_dataset, object_names, random_language_targets

pytestmark = pytest.mark.stability_group("numerics")

# -- states -------------------------------------------------------------------------------------------------------


def test_states_exactly_0_and_1(ctx: CaseContext, outcome: Outcome) -> None:
    """given states of exactly 0 and 1 (the ends of the k axis) and learned states supervised by key frames of
    exactly 0 and 1 train with finite loss and gradients, the loss decreases, renders at 0 and 1 are finite"""
    root = ctx.folder("states-0-1")

    def binary(i: int, n: int) -> dict[str, float]:
        return {name: float((i + j) % 2) for j, name in enumerate(object_names(2))}

    ds = hand_built_dataset(root / "ds", states=binary)
    given = train_briefly(ds.root, root / "given", steps=ctx.steps)
    require_learning(given, "given states")
    learned = train_briefly(ds.root, root / "learned", steps=ctx.steps, overrides=["model.state.mode=learned"])
    require_learning(learned, "learned states")
    assert "state_mse" in learned.last_terms, "learned mode did not report a state_mse term"
    model = given.trainer.model.eval()
    batch = given.trainer.eval_rays.batch(torch.arange(64))
    for value in (0.0, 1.0):
        batch.rays.states = torch.full_like(batch.rays.states, value)
        with torch.no_grad():
            out = model(batch.rays, step=given.trainer.step)
        assert bool(torch.isfinite(out["rgb"]).all()), f"render at state {value} is not finite"
    outcome.record(f"given: {given.summary()}; learned: {learned.summary()}",
                   {"given_loss": [given.first, given.last], "learned_loss": [learned.first, learned.last],
                    "learned_state_mse": learned.last_terms["state_mse"]})


def test_states_outside_unit_range(ctx: CaseContext, outcome: Outcome) -> None:
    """states outside [0, 1] in transforms.json are clamped to [0, 1] when read for training, with a warning that
    names the frame; training stays finite"""
    root = ctx.folder("states-outside")
    ds = hand_built_dataset(root / "ds")
    tpath = ds.root / "transforms.json"
    data = json.loads(tpath.read_text())
    data["frames"][2]["state"]["object0"] = 1.3
    data["frames"][5]["state"]["object1"] = -0.2
    tpath.write_text(json.dumps(data))
    bad_frames = [data["frames"][2]["file_path"], data["frames"][5]["file_path"]]
    stderr = io.StringIO()
    with warnings.catch_warnings(record=True) as caught, contextlib.redirect_stderr(stderr):
        warnings.simplefilter("always")
        trainer = make_trainer(ds.root, root / "run", steps=ctx.steps)
    said = " ".join(str(w.message) for w in caught) + " " + stderr.getvalue()
    states = torch.cat([trainer.train_rays.states, trainer.eval_rays.states])
    assert float(states.min()) >= 0.0 and float(states.max()) <= 1.0, (
        f"states in [{float(states.min()):.2f}, {float(states.max()):.2f}] reach the model unclamped "
        "(the stage that reads transforms.json states should clamp them to [0, 1])")
    for frame in bad_frames:
        fid = Path(frame).stem
        assert fid in said or frame in said, f"no warning names {frame} (out-of-range state); got {said.strip()!r}"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the clamp warning was checked above; -W error must not turn it into a crash
        run = train_briefly(ds.root, root / "run2", steps=ctx.steps)
    require_learning(run, "clamped states")
    outcome.record(f"clamped, warning names {len(bad_frames)} frames; {run.summary()}",
                   {"loss": [run.first, run.last]})


def test_partial_key_frames(ctx: CaseContext, outcome: Outcome) -> None:
    """learned states supervised by key frames that leave an object out (one key frame annotates object0 only:
    its object1 state is NaN, meaning unknown) train with finite state_mse, no step skipped, and fit"""
    root = ctx.folder("partial-key-frames")
    ds = hand_built_dataset(root / "ds")
    partial = sorted(ds.key_frames)[1]
    ds.key_frames[partial].pop("object1")
    write_scene(ds, ds.root)
    run = train_briefly(ds.root, root / "run", steps=ctx.steps, overrides=["model.state.mode=learned"])
    key_states = np.asarray(run.trainer.model.key_states.cpu(), dtype=float)
    assert int(np.isnan(key_states).sum()) == 1, (
        f"the key states {key_states.tolist()} do not hold exactly the one unknown state as NaN")
    require_learning(run, "partial key frames")
    assert math.isfinite(run.last_terms.get("state_mse", math.nan)), "state_mse missing or not finite"
    outcome.record(f"key frame {partial} without object1 (NaN key state); {run.summary()}; state_mse "
                   f"{run.last_terms['state_mse']:.3g}",
                   {"key_states": [[None if math.isnan(v) else v for v in row] for row in key_states.tolist()],
                    "loss": [run.first, run.last],
                    "state_mse": run.last_terms["state_mse"]})


def test_step_change_stiff_capture(ctx: CaseContext, outcome: Outcome) -> None:
    """the `stiff` capture (a door jumping 0 -> 1 between adjacent frames) trains with finite loss and gradients
    and the loss decreases, with given states and with learned states supervised by a key frame on every frame
    (so two adjacent key frames hold 0 and 1); its truth really contains the jump"""
    data = capture_dataset(ctx.workdir, ctx.captures, "stiff", n_frames=8 if ctx.quick else 16)
    ds = read_scene(data)
    states = ds.state_matrix()
    jump = float(np.abs(np.diff(states, axis=0)).max())
    assert jump >= 0.99, f"the stiff capture's largest state change between adjacent frames is {jump:.2f}, not a step"
    run = train_briefly(data, ctx.folder("stiff-run"), steps=ctx.steps)
    require_learning(run, "stiff capture")
    render = render_held_out(run)
    # learned states supervised on every frame: the state network must fit the jump between adjacent key frames
    learned = train_briefly(data, ctx.folder("stiff-learned"), steps=ctx.steps,
                            overrides=["model.state.mode=learned", "model.state.key_frame_every=1"])
    require_learning(learned, "stiff capture, learned states with the jump between adjacent key frames")
    outcome.record(f"jump {jump:.2f} between adjacent frames; given: {run.summary()}; held-out PSNR "
                   f"{render['psnr']:.1f}; learned from per-frame key frames: {learned.summary()}",
                   {"max_adjacent_jump": jump, "loss": [run.first, run.last], **render,
                    "learned_loss": [learned.first, learned.last],
                    "learned_state_mse": learned.last_terms.get("state_mse")})


# -- geometry -----------------------------------------------------------------------------------------------------


def test_objects_touching_box(ctx: CaseContext, outcome: Outcome) -> None:
    """fields sampled exactly on and just outside the faces and corners of the scene box give finite values and
    gradients; a capture whose objects stand against the walls (the box faces) trains finitely"""
    cfg = ModelConfig()
    cfg.field.base_resolution, cfg.field.channels, cfg.field.scales = 8, 4, [1, 2]
    field = RadianceField(cfg.field, 4)
    prob = ProbabilityField(cfg.probability, 2)
    corners = torch.tensor(np.array(np.meshgrid(*[[-1.0, 1.0]] * 4)).reshape(4, -1).T, dtype=torch.float32)
    faces = torch.tensor([[1.0, 0.2, -0.3, 0.5], [-1.0, 1.0, 0.0, -1.0], [1.0 + 1e-6, 0.0, 0.0, 0.0],
                          [-1.0 - 1e-6, 1.0 + 1e-6, 0.3, 1.0]])
    # unclamped: the fields themselves must stay finite just outside the box (the model clamps its samples too,
    # but a clamp here would make the case blind to what the fields do there)
    coords = torch.cat([corners, faces]).requires_grad_(True)
    gen = torch.Generator().manual_seed(0)
    dirs = torch.nn.functional.normalize(torch.randn(len(coords), 3, generator=gen), dim=-1)
    sigma, rgb = field(coords, dirs)
    logits = prob(coords[:, :3], torch.rand(len(coords), 2))
    (sigma.sum() + rgb.sum() + logits.sum()).backward()
    assert bool(torch.isfinite(sigma).all() & torch.isfinite(rgb).all() & torch.isfinite(logits).all()), (
        "field values at the box faces are not finite")
    grads = [p.grad for p in [*field.parameters(), *prob.parameters()] if p.grad is not None]
    assert all(bool(torch.isfinite(g).all()) for g in grads), "gradients at the box faces are not finite"
    # the border vertices of the planes must receive gradient (a sample on the face reaches the last grid vertex)
    plane = field.encoding.grids[0].plane_groups[0]  # the stacked spatial planes; xy first
    border = float(plane.grad[0, ..., -1].abs().sum() + plane.grad[0, ..., 0].abs().sum())
    assert border > 0, "no gradient reaches the border vertices of the xy plane from samples on the box faces"
    values = {"probe_points": len(coords), "border_grad": border}
    metric = f"{len(coords)} face/corner samples finite, border-vertex gradient {border:.2g}"
    # a capture whose objects' backs stand on the room walls: the truth scene box is the room
    data = capture_dataset(ctx.workdir, ctx.captures, "demo", n_frames=8)
    spec = yaml.safe_load((ctx.workdir / "capture-demo" / "truth" / "spec.yaml").read_text())
    box = np.asarray(json.loads((ctx.workdir / "capture-demo" / "truth" / "scene.json").read_text())["scene_box"])
    # objects stand on the floor (z = box min) and, yaw 0, their backs reach position y + depth / 2
    touching = [o["name"] for o in spec["objects"] if abs(o["position"][2] - box[0][2]) < 1e-9
                or abs(o["position"][1] + o["size"][1] / 2 - box[1][1]) < 1e-9]
    assert bool(touching), f"no object of the demo capture touches its scene box {box.tolist()}"
    run = train_briefly(data, ctx.folder("touching-run"), steps=ctx.steps)
    require_learning(run, "demo capture, objects against the box faces")
    values["touching_objects"] = touching
    values["loss"] = [run.first, run.last]
    outcome.record(f"{metric}; demo capture ({', '.join(touching)} on the box faces) {run.summary()}", values)


def test_rays_missing_the_box(ctx: CaseContext, outcome: Outcome) -> None:
    """rays that miss the scene box, graze a face, run along an axis or start inside it get finite near/far,
    render what is behind them (accumulation ~0 for misses: the configured background, or with
    model.sampling.background_mode last_sample their last sample's colour) and give finite loss and gradients"""
    root = ctx.folder("rays-miss")
    ds = hand_built_dataset(root / "ds")
    trainer = make_trainer(ds.root, root / "run", steps=ctx.steps)
    origins = torch.tensor([[3.0, 0, 0], [3.0, 0, 0], [0, 0, 5.0], [1.0, 1.0, 3.0], [0.0, 0.0, 0.0],
                            [-3.0, 0.5, 0.5], [3.0, 3.0, 3.0], [0.0, 2.0, 0.0]])
    dirs = torch.tensor([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0], [0, 0, -1.0], [0.3, -0.2, 0.9],
                         [1.0, 0, 0], [-1.0, -1.0, -1.0], [0.0, 0.0, 1.0]])
    misses = torch.tensor([True, True, True, False, False, False, False, True])  # [3]: grazes the x=y=1 edge
    dirs = torch.nn.functional.normalize(dirs, dim=-1)
    nears, fars = aabb_near_far(origins, dirs, 0.05)
    assert bool(torch.isfinite(nears).all() & torch.isfinite(fars).all() & (fars > nears).all()), (
        f"near/far not finite or empty: {nears.tolist()} {fars.tolist()}")
    n = len(origins)
    rays = RayBundle(origins, dirs, nears, fars, torch.rand(n, 2), torch.zeros(n))
    model = trainer.model
    final: dict = {}
    level = model._level

    def keep_final(*args, **kwargs):  # the last level's per-sample colours: what last_sample shows behind a ray
        result = level(*args, **kwargs)
        if kwargs.get("final"):
            final.update(result)
        return result

    model._level = keep_final
    out = model(rays, step=0, generator=torch.Generator().manual_seed(0))
    del model._level
    loss = (out["rgb"] - 0.5).square().mean() + out["logits"].square().mean() * 1e-3
    loss.backward()
    assert bool(torch.isfinite(loss)), "loss on rays missing the box is not finite"
    bad = nonfinite_grads(model)
    assert not bad, f"non-finite gradients from rays missing the box: {bad[:3]}"
    acc = out["accumulation"].detach()
    last_sample = trainer.config.model.sampling.background_mode == "last_sample"
    behind = final["rgb"].detach()[:, -1, :][misses] if last_sample else model.background
    bg_err = float((out["rgb"].detach()[misses] - behind).abs().max())
    assert float(acc[misses].max()) < 1e-2, f"rays that miss the box accumulate {float(acc[misses].max()):.3g}"
    assert bg_err < 1e-2, f"rays that miss the box do not show the background (error {bg_err:.3g})"
    outcome.record(f"{int(misses.sum())} misses: accumulation <= {float(acc[misses].max()):.1e}, background error "
                   f"{bg_err:.1e}; loss and gradients finite",
                   {"miss_accumulation_max": float(acc[misses].max()), "background_error": bg_err})


# -- densities and precision --------------------------------------------------------------------------------------


def _reference_weights(density: torch.Tensor, deltas: torch.Tensor) -> torch.Tensor:
    """The rendering weights in float64 (where neither cancellation nor a long product loses digits)."""
    tau = density.double() * deltas.double()
    before = torch.cat([torch.zeros_like(tau[:, :1]), torch.cumsum(tau[:, :-1], dim=-1)], dim=-1)
    return torch.exp(-before) * -torch.expm1(-tau)


WEIGHTS_REL_TOL = 1e-5
"""Relative error allowed against float64. Measured: log space 1.6e-7 (tiny tau) and 4.8e-7 (long ray); a
product of (1 - alpha) 1.3e-2 and 3.1e-5; exp(-T_i) - exp(-T_(i+1)) 4.6e-2 and 1.8e-4."""


def test_extreme_densities(ctx: CaseContext, outcome: Outcome) -> None:
    """volume-rendering weights stay finite, in [0, 1] and sum to <= 1 for densities from 0 to inf; they match a
    float64 reference within 1e-5 relative on a ray of tiny optical depth (tau = 1e-6 per sample, where
    exp(-T_i) - exp(-T_(i+1)) cancels and 1 - alpha rounds) and on a 4096-sample ray (where a running product
    drifts): log-space transmittance; the truncated exp has finite values and gradients at |x| = 1e4;
    training with the density bias at +100 and -100 (past float32's exp range) stays finite"""
    density = torch.tensor([[0.0, 1e-30, 1e-8, 1.0, 1e3, 1e8, 1e30, float("inf")],
                            [float("nan"), 0.0, 1e38, 0.0, 0.0, 0.0, 0.0, 0.0],
                            [1e-30] * 8, [50.0] * 8])
    deltas = torch.full_like(density, 0.01)
    w = render_weights(density, deltas)
    assert bool(torch.isfinite(w).all()), f"weights not finite: {w}"
    assert bool((w >= 0).all() & (w <= 1).all()), "weights outside [0, 1]"
    assert float(w.sum(-1).max()) <= 1.0 + 1e-6, f"weights sum to {float(w.sum(-1).max())} > 1"
    assert float(w[0, 6]) > 0.999 or float(w[0, :6].sum()) > 0.999, "an opaque sample did not stop the ray"
    abs_err = float((w[2:].double() - _reference_weights(density[2:], deltas[2:])).abs().max())
    assert abs_err < 1e-6, f"weights differ from the float64 reference by {abs_err:.2e}"
    # relative error where the forms differ: tiny optical depth per sample, and a long ray (total depth ~4)
    rel_err = {}
    for name, samples, tau in (("tiny_tau", 64, 1e-6), ("long_ray", 4096, 1e-3)):
        d, dt = torch.full((1, samples), tau / 0.01), torch.full((1, samples), 0.01)
        ref = _reference_weights(d, dt)
        rel_err[name] = float(((render_weights(d, dt).double() - ref).abs() / ref).max())
        assert rel_err[name] < WEIGHTS_REL_TOL, (
            f"{name} ({samples} samples of optical depth {tau:g}): weights differ from float64 by "
            f"{rel_err[name]:.2e} relative (> {WEIGHTS_REL_TOL:g}): transmittance is not computed in log space")
    x = torch.tensor([-1e4, -100.0, 0.0, 15.0, 100.0, 1e4], requires_grad=True)
    y = trunc_exp(x, 15.0)
    y.sum().backward()
    assert bool(torch.isfinite(y).all() & torch.isfinite(x.grad).all()), "truncated exp not finite at |x| = 1e4"
    root = ctx.folder("densities")
    ds = hand_built_dataset(root / "ds")
    runs = {}
    # +-100 is past float32 exp's range (overflow above ~88): only the fields' clamped exp keeps these finite
    for bias in (100.0, -100.0):
        run = train_briefly(ds.root, root / f"run{bias:+g}", steps=ctx.steps,
                            overrides=[f"model.field.density_bias={bias}"])
        assert run.skipped == 0, f"density bias {bias:+g}: {run.skipped} steps skipped as non-finite"
        render_held_out(run)
        runs[bias] = run
    high, low = runs[100.0], runs[-100.0]
    outcome.record(f"weights finite for 0..inf, float64 error {abs_err:.1e} abs, {rel_err['tiny_tau']:.1e} rel "
                   f"(tau 1e-6), {rel_err['long_ray']:.1e} rel (4096 samples); bias +100: {high.summary()}; "
                   f"bias -100: {low.summary()}",
                   {"reference_error": abs_err, "relative_error": rel_err,
                    "bias_plus100_loss": [high.first, high.last], "bias_minus100_loss": [low.first, low.last]})


AUTOCAST_RGB_TOL = {torch.bfloat16: 1e-3, torch.float16: 1e-4}
"""rgb error allowed against float32: about 5x the largest measured (bf16 1.8e-4 / 2.0e-4 and fp16 1.5e-5 /
2.4e-5, quick / full); rendering in half precision adds about 2e-4."""


def _autocast_check(ctx: CaseContext, device: str, dtype: torch.dtype) -> tuple[str, dict]:
    """Forward + backward of a whole batch (the main field's activations are the largest) under autocast;
    returns the metric and the values."""
    root = ctx.folder(f"autocast-{device}-{str(dtype).replace('torch.', '')}")
    ds = hand_built_dataset(root / "ds", width=32, height=24)
    # the main field at its cpu-demo width (2 scales x 16 channels, 64-wide MLPs): its activations are the largest
    size = ["model.field.base_resolution=64", "model.field.channels=16", "model.field.scales=[1,2]",
            "model.field.hidden=64", "model.field.color_hidden=64", "model.sampling.num_samples=24"]
    rays = 256 if ctx.quick else 1024
    # with a language table: its Gram matrix loses the entries' norms in reduced precision
    targets = random_language_targets(root / "targets.npz", ds.objects)
    trainer = make_trainer(ds.root, root / "run", steps=ctx.steps, device=device,
                           overrides=[*size, f"train.batch_rays={rays}", f"language_targets={targets}"])
    model = trainer.model
    batch = trainer.train_rays.sample(rays, torch.Generator().manual_seed(1))

    def forward(enabled: bool) -> tuple[dict, torch.Tensor, dict[str, torch.Tensor]]:
        model.zero_grad(set_to_none=True)
        gen = torch.Generator(device=trainer.device).manual_seed(2)
        with torch.autocast(device_type=device, dtype=dtype, enabled=enabled):
            out = model(batch.rays, step=0, generator=gen)
            terms = model.loss_dict(out, batch, 0, trainer.language)
        loss = sum(terms.values())
        loss.backward()
        return out, loss, terms

    ref, ref_loss, _ = forward(False)
    ref_rgb = ref["rgb"].detach().float()
    # proof that both MLPs really ran in reduced precision: the dtype of their first layers' outputs
    seen: dict[str, list[torch.dtype]] = {"density": [], "colour": []}
    hooks = []
    for name, mlp in (("density", model.field.density_mlp), ("colour", model.field.color_mlp)):
        first = next(m for m in mlp.modules() if isinstance(m, torch.nn.Linear))
        hooks.append(first.register_forward_hook(lambda m, i, o, name=name: seen[name].append(o.dtype)))
    # and that volume rendering stays float32: every call's weights against float32 from the same inputs
    rendered: list[tuple[torch.Tensor, torch.Tensor, torch.Tensor]] = []

    def watched_weights(density: torch.Tensor, deltas: torch.Tensor) -> torch.Tensor:
        weights = render_weights(density, deltas)
        rendered.append((density.detach(), deltas.detach(), weights.detach()))
        return weights

    # and the language table's rendering: float32 and equal to a float32 render of the same region weights
    table = model.language_table
    assert table is not None, "the autocast case trains no language table"
    languages: list[tuple[torch.Tensor, torch.Tensor, torch.Tensor]] = []
    table_render = table.render

    def watched_language(region_weights: torch.Tensor, values: torch.Tensor) -> torch.Tensor:
        emb = table_render(region_weights, values)
        languages.append((region_weights.detach(), values.detach(), emb.detach()))
        return emb

    with mock.patch.object(livescene, "render_weights", watched_weights), \
            mock.patch.object(table, "render", watched_language):
        out, loss, terms = forward(True)
    for hook in hooks:
        hook.remove()
    for name, dtypes in seen.items():
        assert dtypes and all(d == dtype for d in dtypes), (
            f"the {name} MLP ran in {set(dtypes)}, not {dtype}: autocast did not reach it")
    assert rendered, "the model did not call render_weights"
    weights_err = 0.0
    for density, deltas, weights in rendered:
        assert weights.dtype == torch.float32, f"rendering weights are {weights.dtype} under autocast, not float32"
        weights_err = max(weights_err, float((weights - render_weights(density, deltas)).abs().max()))
    assert weights_err <= 1e-7, (
        f"rendering weights under {dtype} autocast differ from float32 ones of the same densities by "
        f"{weights_err:.2e}: volume rendering ran in reduced precision")
    assert languages, "the model did not render its language table"
    language_err = 0.0
    for region_weights, values, emb in languages:
        assert emb.dtype == torch.float32, f"the rendered language embedding is {emb.dtype} under autocast"
        with torch.no_grad():
            language_err = max(language_err, float((emb - table_render(region_weights.float(), values.float()))
                                                   .abs().max()))
    assert language_err <= 1e-6, (
        f"the language table's render under {dtype} autocast differs from float32 by {language_err:.2e}: its "
        "Gram matrix ran in reduced precision")
    assert "language" in terms, "no language loss term under autocast"
    low = {k: v.dtype for k, v in terms.items() if v.dtype != torch.float32}
    assert not low, f"loss terms under {dtype} autocast are not float32: {low}"
    assert bool(torch.isfinite(loss)), f"{dtype} autocast loss is not finite"
    bad = nonfinite_grads(model)
    assert not bad, f"{dtype} autocast gradients not finite: {bad[:3]}"
    for key in ("rgb", "depth", "accumulation", "logits"):
        assert bool(torch.isfinite(out[key]).all()), f"{dtype} autocast {key} not finite"
    rgb_err = float((out["rgb"].detach().float() - ref_rgb).abs().max())
    loss_rel = abs(float(loss.detach()) - float(ref_loss.detach())) / max(abs(float(ref_loss.detach())), 1e-12)
    tol = AUTOCAST_RGB_TOL[dtype]
    assert rgb_err < tol, f"{dtype} autocast rgb differs from float32 by {rgb_err:.3g} (> {tol})"
    samples = rays * model.config.sampling.num_samples
    width = model.field.encoding.out_dim
    # and the trainer's own path: train.mixed_precision on this device, a few steps, the loss must go down
    precision = "bf16" if dtype == torch.bfloat16 else "fp16"
    run = train_briefly(ds.root, root / "trained", steps=ctx.steps, device=device,
                        overrides=[f"train.mixed_precision={precision}"])
    assert run.trainer.amp_dtype == dtype, (
        f"train.mixed_precision={precision} on {device} gave autocast "
        f"{run.trainer.amp_dtype}")
    require_learning(run, f"training with {precision} autocast on {device}")
    return (f"{samples} x {width} field activations: max rgb error {rgb_err:.1e} (< {tol:g}), loss rel. error "
            f"{loss_rel:.1e} vs float32; {len(rendered)} render_weights calls float32 (error {weights_err:.0e}), "
            f"language table float32 (error {language_err:.0e}), {len(terms)} loss terms float32; trainer with "
            f"mixed_precision={precision}: {run.summary()}",
            {"rgb_max_error": rgb_err, "loss_rel_error": loss_rel, "weights_error": weights_err,
             "language_error": language_err,
             "activations": [samples, width], "trained_loss": [run.first, run.last]})


@pytest.mark.parametrize("dtype", [
    pytest.param(torch.bfloat16, id="cpu_bf16", marks=pytest.mark.stability_checks(
        "a training forward + backward under CPU bf16 autocast (the main field's density and colour MLPs really "
        "run in bf16) gives finite outputs and gradients, volume-rendering weights, the language table's "
        "render and loss terms float32 (each equal to a float32 one of the same inputs), rgb within 1e-3 of "
        "float32; training with train.mixed_precision=bf16 fits the colours")),
    pytest.param(torch.float16, id="cpu_fp16", marks=pytest.mark.stability_checks(
        "the same under CPU fp16 autocast: finite, rendering and losses float32, rgb within 1e-4 of float32; "
        "train.mixed_precision=fp16 fits the colours")),
])
def test_autocast(ctx: CaseContext, outcome: Outcome, dtype: torch.dtype) -> None:
    """CPU autocast in bf16 and fp16 (cases autocast_cpu_bf16, autocast_cpu_fp16)."""
    outcome.record(*_autocast_check(ctx, "cpu", dtype))


def test_autocast_cuda(ctx: CaseContext, outcome: Outcome) -> None:
    """the same under CUDA bf16 and fp16 autocast (skipped without a GPU)"""
    if not torch.cuda.is_available():
        pytest.skip("torch sees no CUDA device on this machine")
    bf_metric, bf_values = _autocast_check(ctx, "cuda", torch.bfloat16)
    fp_metric, fp_values = _autocast_check(ctx, "cuda", torch.float16)
    outcome.record(f"bf16: {bf_metric}; fp16: {fp_metric}", {"bf16": bf_values, "fp16": fp_values})


# -- masks and objects --------------------------------------------------------------------------------------------


def test_near_empty_masks(ctx: CaseContext, outcome: Outcome) -> None:
    """frames where an object covers a single pixel (under H*W/300) are marked unreliable and left out of the
    mask losses; an object absent from a frame is fine; training is finite and the loss decreases"""
    root = ctx.folder("near-empty")
    base = band_labels(2)

    def labels(i: int, h: int, w: int) -> np.ndarray:
        out = base(i, h, w)
        if i % 2 == 0:  # object0 shrinks to one pixel, object1 disappears
            out[out < 2] = 2
            out[h - 1, 0] = 0
        elif i % 4 == 1:  # object1 out of view, object0 as usual: a frame to keep
            out[out == 1] = 2
        return out

    ds = hand_built_dataset(root / "ds", labels=labels)
    run = train_briefly(ds.root, root / "run", steps=ctx.steps)
    require_learning(run, "near-empty masks")
    labels_t = run.trainer.train_rays.labels
    frames = run.trainer.train_rays.frames
    unreliable = [f.file_path for k, f in enumerate(frames) if bool((labels_t[k] == -1).all())]
    expected = [f.file_path for k, f in enumerate(frames) if int(f.frame_id) % 2 == 0]
    assert unreliable == expected, f"unreliable frames {unreliable}, expected the one-pixel frames {expected}"
    absent = [k for k, f in enumerate(frames) if int(f.frame_id) % 4 == 1]
    assert absent and all(bool((labels_t[k] == 0).any()) and not bool((labels_t[k] == 1).any()) for k in absent), (
        "the frames without object1 should keep their labels (object0 and background) for the mask losses")
    assert math.isfinite(run.last_terms.get("focal_mask", math.nan)), "focal mask loss missing or not finite"
    outcome.record(f"{len(unreliable)} one-pixel frames skipped by the mask losses, {len(absent)} without object1 "
                   f"kept; {run.summary()}",
                   {"unreliable_frames": len(unreliable), "absent_object_frames": len(absent),
                    "loss": [run.first, run.last]})


def test_object_fills_view(ctx: CaseContext, outcome: Outcome) -> None:
    """frames where one object covers every pixel (no background, no label pairs to repel) train with finite
    focal and repulsion losses and the loss decreases"""
    root = ctx.folder("fills-view")
    base = band_labels(2)

    def labels(i: int, h: int, w: int) -> np.ndarray:
        return np.zeros((h, w), dtype=np.int64) if i % 2 == 0 else base(i, h, w)

    ds = hand_built_dataset(root / "ds", labels=labels)
    run = train_briefly(ds.root, root / "run", steps=ctx.steps)
    require_learning(run, "object filling the view")
    rays = run.trainer.train_rays
    full = [f for k, f in enumerate(rays.frames) if bool((rays.labels[k] == 0).all())]
    assert len(full) > 0, "no training frame is filled by the object"
    outcome.record(f"{len(full)} training frames filled by one object; {run.summary()}",
                   {"filled_frames": len(full), "loss": [run.first, run.last]})


def test_ten_objects(ctx: CaseContext, outcome: Outcome) -> None:
    """a scene with 10 objects trains with finite loss and gradients, the loss decreases, the rendered
    probabilities have 11 channels, and the radiance field has as many parameters as with 2 objects"""
    root = ctx.folder("ten-objects")
    ds = hand_built_dataset(root / "ds", n_objects=10, width=40, height=20)
    run = train_briefly(ds.root, root / "run", steps=ctx.steps)
    require_learning(run, "10 objects")
    render = render_held_out(run)
    two = make_trainer(hand_built_dataset(root / "ds2", n_objects=2).root, root / "run2", steps=1)
    n10 = sum(p.numel() for p in run.trainer.model.field.parameters())
    n2 = sum(p.numel() for p in two.model.field.parameters())
    assert n10 == n2, f"radiance field has {n10} parameters with 10 objects but {n2} with 2"
    logits = run.trainer.model.eval()(run.trainer.eval_rays.batch(torch.arange(8)).rays)["logits"]
    assert logits.shape[-1] == 11, f"probabilities have {logits.shape[-1]} channels, expected 11"
    outcome.record(f"{run.summary()}; field parameters {n10} (same as 2 objects); held-out PSNR {render['psnr']:.1f}",
                   {"loss": [run.first, run.last], "field_params": n10, **render})


def test_stress_capture(ctx: CaseContext, outcome: Outcome) -> None:
    """the `stress` capture (10 objects) trains with finite loss and gradients and the loss decreases"""
    data = capture_dataset(ctx.workdir, ctx.captures, "stress", width=48, height=36, n_frames=8)
    run = train_briefly(data, ctx.folder("stress-run"), steps=ctx.steps)
    require_learning(run, "stress capture")
    n = len(run.trainer.ds.objects)
    assert n >= 10, f"the stress capture has {n} objects, expected 10"
    outcome.record(f"{n} objects; {run.summary()}", {"objects": n, "loss": [run.first, run.last]})


# -- units --------------------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def metres_run(ctx: CaseContext) -> BriefRun:
    """The room in metres, trained once: both units checks compare their loss curve with it."""
    return train_briefly(hand_built_dataset(ctx.folder("units-1") / "ds").root, ctx.workdir / "units-1" / "run",
                         steps=ctx.steps)


@pytest.mark.parametrize("scale", [
    pytest.param(1000.0, id="1000x", marks=pytest.mark.stability_checks(
        "the same room with every length x1000 (scene box, poses) trains finitely and like the room in metres "
        "(loss curve within 1e-3 relative)")),
    pytest.param(0.001, id="0.001x", marks=pytest.mark.stability_checks(
        "the same room with every length x0.001 trains finitely and like the room in metres (within 1e-3)")),
])
def test_units(ctx: CaseContext, outcome: Outcome, metres_run: BriefRun, scale: float) -> None:
    """The same room in other units (cases units_1000x, units_0.001x)."""
    root = ctx.folder(f"units-{scale:g}")
    ds = hand_built_dataset(root / "ds", units_scale=scale)
    run = train_briefly(ds.root, root / "run", steps=ctx.steps)
    require_learning(run, f"{scale:g}x units")
    rel = max(abs(a - b) / max(abs(b), 1e-12) for a, b in zip(run.losses, metres_run.losses, strict=True))
    assert rel < 1e-3, f"{scale:g}x units train differently from metres: loss rel. difference {rel:.2e}"
    depth = render_held_out(run)
    extent = float(np.max(ds.scene_box[1] - ds.scene_box[0]))
    outcome.record(f"box {extent:g} units; {run.summary()}; loss within {rel:.1e} of the same scene in metres",
                   {"loss": [run.first, run.last], "max_rel_loss_difference": rel, **depth})


def test_extreme_capture(ctx: CaseContext, outcome: Outcome) -> None:
    """the `extreme` capture (1000x units) trains with finite loss and gradients and the loss decreases"""
    data = capture_dataset(ctx.workdir, ctx.captures, "extreme", n_frames=8)
    run = train_briefly(data, ctx.folder("extreme-run"), steps=ctx.steps)
    require_learning(run, "extreme capture")
    box = run.trainer.ds.scene_box
    extent = float(np.max(box[1] - box[0])) if box is not None else math.nan
    outcome.record(f"scene box extent {extent:g} units; {run.summary()}", {"extent": extent,
                                                                         "loss": [run.first, run.last]})


