"""Train a tiny LiveScene for a few steps and collect what the stability checks check.

The config is the ``cpu-demo`` preset shrunk to a few hundred parameters per
plane, so a step takes milliseconds; the trainer, its non-finite guards and the
model code are exactly those of ``livescene train``. The checks here are plain
``assert`` statements that conftest.py registers for pytest's assertion
rewriting, so they hold under ``python -O`` as they do in the test modules.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch

from stages.model import Trainer, TrainingDiverged, load_config
from stages.model.tiny_overrides import TINY_MODEL_OVERRIDES

TINY_MODEL = [
    *TINY_MODEL_OVERRIDES,
    "train.batch_rays=64", "train.warmup_steps=2", "train.eval_every=0", "train.eval_rays=256",
    "train.checkpoint_every=0", "train.render_chunk=512", "train.threads=0",
    # no wall-clock budget: with one, the LR decay follows elapsed time and no two runs are bit-identical
    "train.max_seconds=0",
]
"""Overrides of the cpu-demo preset that make a step take milliseconds on one core, reproducibly."""


@dataclass
class BriefRun:
    """What a few training steps produced."""

    trainer: Any
    """The stages.model Trainer (model, rays, optimiser) after the steps."""
    losses: list[float] = field(default_factory=list)
    """Total loss of every step that was taken (skipped steps have none)."""
    skipped: int = 0
    """Steps the trainer skipped for a non-finite loss or gradient."""
    first_terms: dict[str, float] = field(default_factory=dict)
    last_terms: dict[str, float] = field(default_factory=dict)
    fit: dict[str, float] = field(default_factory=dict)
    """What require_learning measured."""
    density_grad: float = math.nan
    """Size of the gradient that reached the main field's density output on the last step."""

    @property
    def first(self) -> float:
        return self.losses[0] if self.losses else math.nan

    @property
    def last(self) -> float:
        return self.losses[-1] if self.losses else math.nan

    def summary(self) -> str:
        fit = f", colour correlation {self.fit['corr']:.2f}" if "corr" in self.fit else ""
        return f"loss {self.first:.4g} -> {self.last:.4g} in {len(self.losses)} steps, {self.skipped} skipped{fit}"


def nonfinite_grads(model: torch.nn.Module) -> list[str]:
    """Names of the parameters whose gradient holds a NaN or inf."""
    return [n for n, p in model.named_parameters() if p.grad is not None and not bool(torch.isfinite(p.grad).all())]


def make_trainer(data: Path, out: Path, *, steps: int, overrides: list[str] | None = None, seed: int = 0,
                 device: str = "cpu") -> Any:
    config = load_config("cpu-demo", [*TINY_MODEL, f"train.max_steps={steps}", *(overrides or [])],
                         data=str(data), seed=seed)
    return Trainer(config, out, device=device, progress=False)


def _watch_density_grad(model: torch.nn.Module, run: BriefRun) -> Any:
    """Hook the main field's density MLP so the step's backward records the gradient of its density column
    (column 0 of its output; the others are the colour MLP's geometry features, which train without it)."""
    mlp = getattr(getattr(model, "field", None), "density_mlp", None)
    if mlp is None:
        return None

    def on_output(module: torch.nn.Module, args: Any, out: torch.Tensor) -> None:
        if out.requires_grad:
            out.register_hook(lambda g: setattr(run, "density_grad", float(g[:, 0].float().abs().sum())))

    return mlp.register_forward_hook(on_output)


def train_briefly(data: Path, out: Path, *, steps: int, overrides: list[str] | None = None, seed: int = 0,
                  device: str = "cpu") -> BriefRun:
    """``steps`` optimisation steps; every taken step's loss and gradients are checked finite."""
    trainer = make_trainer(data, out, steps=steps, overrides=overrides, seed=seed, device=device)
    run = BriefRun(trainer)
    for k in range(steps):
        hook = _watch_density_grad(trainer.model, run) if k == steps - 1 else None
        trainer.train_step()
        if hook is not None:
            hook.remove()
        try:
            result = trainer.flush_steps()[-1]
        except TrainingDiverged as exc:  # a failed check (its steps were not finite), not a crash of the check
            raise AssertionError(f"step {trainer.step}: training diverged: {exc}") from exc
        trainer.step += 1
        if result is None:
            run.skipped += 1
            continue
        assert all(math.isfinite(v) for v in result.values()), f"step {trainer.step}: non-finite loss {result}"
        bad = nonfinite_grads(trainer.model)
        assert not bad, f"step {trainer.step}: non-finite gradients in {bad[:3]}"
        if not run.losses:
            run.first_terms = dict(result)
        run.last_terms = dict(result)
        run.losses.append(float(result["loss"]))
    bad = [n for n, p in trainer.model.named_parameters() if not bool(torch.isfinite(p).all())]
    assert not bad, f"parameters not finite after training: {bad[:3]}"
    return run


FIT_CORRELATION = 0.15
"""Least correlation of rendered and true colours on training rays after a brief training. Measured (docs/stability.md):
0.26-0.70 over the cases (12 steps) and 0.40-0.73 (60 steps); a model that renders one colour whatever its
inputs stays within +-0.08."""


def require_learning(run: BriefRun, what: str) -> dict[str, float]:
    """The 'useful result' half of a check: no skipped step, the colours fit, and the density learns.

    The total loss alone falls even for a model that renders one grey whatever its inputs (its regularisers
    fall by themselves). A few steps do not yet beat the images' mean colour in PSNR, but the rendered colours
    already follow the images: their correlation over training rays must reach FIT_CORRELATION. The colour
    MLP alone could fit that, so the gradient must also reach the main field's density output.
    Returns the measured fit (also kept as ``run.fit``).
    """
    assert run.skipped == 0, (
        f"{what}: {run.skipped} of {run.skipped + len(run.losses)} steps were skipped as "
        "non-finite")
    fit = render_held_out(run, 512, train=True)
    assert fit["corr"] >= FIT_CORRELATION, (
        f"{what}: the colours do not fit: rendered and true colours of training rays correlate by "
        f"{fit['corr']:.3f} < {FIT_CORRELATION} ({run.summary()})")
    assert run.density_grad > 0, (
        f"{what}: no gradient reached the main field's density on the last step ({run.density_grad}): "
        "the field cannot learn geometry")
    fit["density_grad"] = run.density_grad
    run.fit = fit
    return fit


@torch.no_grad()
def render_held_out(run: BriefRun, n_rays: int = 256, train: bool = False) -> dict[str, float]:
    """Render held-out (or, with ``train``, training) rays in eval mode; every output must be finite.

    Returns the PSNR, that of the best constant colour (the rays' mean), the correlation of rendered and true
    colours (0 for a constant render) and the accumulation range."""
    trainer = run.trainer
    model = trainer.model
    model.eval()
    rays = trainer.train_rays if train else trainer.eval_rays
    idx = torch.arange(0, rays.n_rays, max(rays.n_rays // n_rays, 1))[:n_rays]
    batch = rays.batch(idx)
    out = model(batch.rays, step=trainer.step)
    model.train()
    for key in ("rgb", "depth", "accumulation", "logits"):
        assert bool(torch.isfinite(out[key]).all()), f"rendered {key} has non-finite values"
    rgb = out["rgb"].clamp(0, 1)
    mse = float((rgb - batch.rgb).square().mean())
    a, b = rgb - rgb.mean(0), batch.rgb - batch.rgb.mean(0)  # b.square().mean(): the best constant colour's error
    corr = float((a * b).sum() / ((a.square().sum() * b.square().sum()).sqrt() + 1e-12))
    acc = out["accumulation"]
    return {"psnr": -10 * math.log10(max(mse, 1e-12)),
            "psnr_constant": -10 * math.log10(max(float(b.square().mean()), 1e-12)), "corr": corr,
            "acc_min": float(acc.min()), "acc_max": float(acc.max())}
