"""Training guards (group ``guards``): a non-finite loss or gradient skips the step, says which term and where,
stops after N in a row, and never writes a checkpoint holding NaN."""

from __future__ import annotations

import contextlib
import hashlib
import io
import math
import re
from pathlib import Path

import pytest
import torch

from stages.model import TrainingDiverged
from stages.stability.collector import Outcome

from .brief_training import make_trainer
from .case_context import CaseContext
from .tiny_scenes import hand_built_dataset

pytestmark = pytest.mark.stability_group("guards")


@pytest.fixture(scope="module")
def dataset(ctx: CaseContext) -> Path:
    """One tiny dataset for every guard check (they only read it)."""
    return hand_built_dataset(ctx.folder("guards-ds") / "ds").root


def _poison_loss(trainer, term: str, on_steps: set[int] | None) -> None:
    """Make ``term`` NaN on ``on_steps`` (None = every step) by wrapping the model's loss_dict."""
    original = trainer.model.loss_dict

    def loss_dict(out, batch, step, language=None):
        terms = original(out, batch, step, language)
        if on_steps is None or step in on_steps:
            terms[term] = terms[term] * float("nan")
        return terms

    trainer.model.loss_dict = loss_dict


def _params(model: torch.nn.Module) -> dict[str, torch.Tensor]:
    return {k: v.detach().clone() for k, v in model.state_dict().items()}


def _optimizer_state(optimizer: torch.optim.Optimizer) -> dict[str, torch.Tensor]:
    """Every tensor of the optimiser's state (Adam: step, exp_avg, exp_avg_sq per parameter), copied."""
    state = optimizer.state_dict()["state"]
    return {f"{i}.{k}": torch.as_tensor(v).detach().clone() for i, s in state.items() for k, v in s.items()}


def test_nonfinite_loss_skipped(ctx: CaseContext, dataset: Path, outcome: Outcome) -> None:
    """a NaN loss term skips the step without touching the weights or the optimiser, the log line names the term
    and the step, the streak resets after a good step and training goes on to a finite model"""
    trainer = make_trainer(dataset, ctx.folder("guard-loss"), steps=8)
    _poison_loss(trainer, "focal_mask", {3, 4})
    log = io.StringIO()
    skipped, before_skip, optimizer_before, optimizer_checked = [], None, {}, 0
    with contextlib.redirect_stderr(log):
        for _ in range(8):
            if trainer.step == 3:
                before_skip = _params(trainer.model)
                optimizer_before = _optimizer_state(trainer.optimizer)
            trainer.train_step()
            result = trainer.flush_steps()[-1]
            if result is None:
                skipped.append(trainer.step)
                assert trainer.nonfinite_streak == len(skipped), (
                    f"streak {trainer.nonfinite_streak} after "
                    f"{len(skipped)} skipped steps")
            elif skipped:
                assert trainer.nonfinite_streak == 0, "the streak did not reset after a finite step"
            if trainer.step == 4 and before_skip is not None:
                after = _params(trainer.model)
                changed = [k for k in before_skip if not torch.equal(before_skip[k], after[k])]
                assert not changed, f"a skipped step changed the weights {changed[:3]}"
                moved = _optimizer_state(trainer.optimizer)
                assert moved.keys() == optimizer_before.keys(), "a skipped step changed the optimiser's state keys"
                changed = [k for k in moved if not torch.equal(moved[k], optimizer_before[k])]
                assert not changed, f"a skipped step changed the optimiser's state {changed[:3]}"
                optimizer_checked = len(moved)
            trainer.step += 1
    assert skipped == [3, 4], f"skipped steps {skipped}, expected [3, 4]"
    assert optimizer_checked > 0, "the optimiser had no state to compare after the skipped steps"
    said = log.getvalue()
    for step in skipped:
        line = next((s for s in said.splitlines() if s.startswith(f"step {step}:")), "")
        assert "focal_mask" in line, f"the log of skipped step {step} does not name the term: {line!r}"
    assert all(bool(torch.isfinite(p).all()) for p in trainer.model.parameters()), "weights not finite at the end"
    first = next(s for s in said.splitlines() if s.startswith("step 3:"))
    outcome.record(f"steps {skipped} skipped, weights and {optimizer_checked} optimiser state tensors (moments, "
                   f"step counts) untouched; log: {first.strip()!r}",
                   {"skipped_steps": skipped, "optimizer_tensors": optimizer_checked})


def test_nonfinite_gradient_skipped(ctx: CaseContext, dataset: Path, outcome: Outcome) -> None:
    """a NaN gradient (finite loss) skips the step, the log names the step and the parameter it appeared in"""
    trainer = make_trainer(dataset, ctx.folder("guard-grad"), steps=4)
    name, param = next((n, p) for n, p in trainer.model.named_parameters() if n.startswith("field.density_mlp"))
    poison = {"on": False}
    param.register_hook(lambda g: g * float("nan") if poison["on"] else g)
    log = io.StringIO()
    with contextlib.redirect_stderr(log):
        results = []
        for step in range(4):
            poison["on"] = step == 2
            trainer.train_step()
            results.append(trainer.flush_steps()[-1])
            trainer.step += 1
    assert [r is None for r in results] == [False, False, True, False], (
        f"skipped pattern {[r is None for r in results]}, expected only step 2")
    line = next((s for s in log.getvalue().splitlines() if s.startswith("step 2:")), "")
    assert "gradient" in line, f"the log of step 2 does not say the gradient was non-finite: {line!r}"
    assert name in line or name.rsplit(".", 1)[0] in line, (
        f"the log of step 2 does not name the parameter with the NaN gradient ({name}): {line!r}")
    outcome.record(f"step 2 skipped; log: {line.strip()!r}", {"parameter": name})


def test_nonfinite_streak_stops(ctx: CaseContext, dataset: Path, outcome: Outcome) -> None:
    """after train.max_nonfinite consecutive non-finite steps training stops with TrainingDiverged naming the
    term, the streak's steps and the last step run (the trainer's own); every checkpoint is finite and those
    written during the streak hold the last good weights; no model.pt or run.json appears"""
    out = ctx.folder("guard-streak")
    trainer = make_trainer(dataset, out, steps=20, overrides=["train.max_nonfinite=3",
                                                                     "train.checkpoint_every=2"])
    _poison_loss(trainer, "rgb", set(range(4, 100)))
    log = io.StringIO()
    try:
        with contextlib.redirect_stderr(log):
            trainer.train()
    except TrainingDiverged as exc:
        message = str(exc)
    else:
        pytest.fail("training with a NaN loss on every step from step 4 did not stop")
    assert "3 consecutive" in message and "rgb" in message, (
        f"the stop message does not give the count and the term: {message!r}")
    # the flags are read once per read-back (here every 2nd step, the checkpoints): the streak (steps 4-6) is
    # seen at one, and the message must name it and the step where training really stopped
    named = re.search(r"\(steps (\d+)-(\d+)\); training stopped after step (\d+)", message)
    assert named, f"the stop message does not name the streak's steps and the last step run: {message!r}"
    first, limit, last = map(int, named.groups())
    assert (first, limit) == (4, 6), f"the message names the streak as steps {first}-{limit}, not 4-6: {message!r}"
    assert last == trainer.step - 1, (
        f"the message says training stopped after step {last}, but the trainer ran steps up to {trainer.step - 1}")
    ckpts = sorted((out / "checkpoints").glob("step_*.pt"))
    steps = [int(p.stem.split("_")[1]) for p in ckpts]
    assert bool(ckpts), "no checkpoint was written before training stopped"
    states = {s: torch.load(p, map_location="cpu", weights_only=False)["model"] for s, p in zip(steps, ckpts,
                                                                                               strict=True)}
    for s, state in states.items():
        assert all(bool(torch.isfinite(v).all()) for v in state.values() if v.is_floating_point()), (
            f"checkpoint of step {s} holds non-finite weights")
    last_good = max(s for s in steps if s <= 4)
    for s in (s for s in steps if s > last_good):  # skipped steps must not have moved the weights
        same = all(torch.equal(states[s][k], states[last_good][k]) for k in states[s])
        assert same, f"checkpoint of step {s} (after the NaN steps began) differs from step {last_good}'s weights"
    assert not (out / "model.pt").exists() and not (out / "run.json").exists(), (
        "a diverged run wrote model.pt or run.json")
    outcome.record(f"{trainer.step} steps run: {message[:110]!r}; checkpoints {steps} finite",
                   {"steps_run": trainer.step, "streak": [first, limit], "checkpoints": steps})


def test_no_nan_checkpoint(ctx: CaseContext, dataset: Path, outcome: Outcome) -> None:
    """saving a checkpoint of weights holding NaN is refused with TrainingDiverged and leaves the checkpoints
    already on disk byte-identical"""
    out = ctx.folder("guard-ckpt")
    trainer = make_trainer(dataset, out, steps=4)
    trainer.train_step()
    trainer.step = 1
    good = trainer.save_checkpoint(1.0)
    digest = hashlib.sha256(good.read_bytes()).hexdigest()
    with torch.no_grad():
        first = next(trainer.model.parameters())
        first[(0,) * first.dim()] = math.nan  # (plane stacks are channels-last: no flat view)
    trainer.step = 2
    try:
        trainer.save_checkpoint(2.0)
    except TrainingDiverged as exc:
        message = str(exc)
    else:
        pytest.fail("a checkpoint of NaN weights was written")
    files = sorted(p.name for p in (out / "checkpoints").iterdir())
    assert files == [good.name], f"checkpoints folder holds {files} after the refused save"
    assert hashlib.sha256(good.read_bytes()).hexdigest() == digest, "the earlier checkpoint changed"
    outcome.record(f"refused: {message!r}", {"files": files})
