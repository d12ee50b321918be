"""The whole training step as CUDA graphs (train.cuda_graphs): the same training as eager steps, never a host sync.

The graph tests need a GPU (CI has none; benchmarks/gpu_check.sh runs them on a lent machine). On the CPU the
setting is ignored, and what the graphs rely on is tested here: a device-tensor anneal exponent gives the
schedule's samples, and the logged learning rate is read from the schedule, not from Adam's device tensor.
"""

from __future__ import annotations

import math

import pytest
import torch
from random_targets import random_language_targets

from stages.model import Trainer
from stages.model.step_counters import count_host_syncs
from stages.model.step_graphs import EAGER_STEPS, StepGraphs

cuda = pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device (CI has none)")
# the schedule's every branch within a few steps: proposal gradients on some steps only, annealing then not
# (proposal gradients from step 11 on every 2nd, from 16 every 3rd step; annealed until step 30)
SCHEDULE = ["model.sampling.anneal_max_steps=30", "model.sampling.update_warmup=16", "model.sampling.update_every=3",
            "train.log_every=1000"]


def _trainer(tiny_dataset, tmp_path, tiny_config, name: str, device: str, *extra: str, steps: int = 40) -> Trainer:
    cfg = tiny_config(tiny_dataset.root, *SCHEDULE, *extra, steps=steps)
    cfg.language_targets = str(random_language_targets(tmp_path / "targets.npz", tiny_dataset.objects))
    return Trainer(cfg, tmp_path / name, device=device, progress=False)


def _queue(trainer: Trainer, n: int) -> None:
    for _ in range(n):
        trainer.train_step()
        trainer.step += 1


def _steps(trainer: Trainer, n: int) -> list[dict | None]:
    _queue(trainer, n)
    return trainer.flush_steps()


def test_a_device_anneal_exponent_samples_as_the_schedule_does(tiny_dataset, tmp_path, tiny_config):
    trainer = _trainer(tiny_dataset, tmp_path, tiny_config, "run", "cpu")
    model, step = trainer.model, 5
    anneal = model.schedule.anneal(step)
    assert 0 < anneal < 1
    batch = trainer.train_rays.sample(64, torch.Generator().manual_seed(0))
    outs = []
    for value in (anneal, torch.tensor(anneal)):
        out = model(batch.rays, step=step, generator=torch.Generator().manual_seed(1), anneal=value)
        outs.append(out["final"][0].bins)
    torch.testing.assert_close(outs[0], outs[1])
    plain = model(batch.rays, step=step, generator=torch.Generator().manual_seed(1), anneal=1.0)
    assert not torch.allclose(plain["final"][0].bins, outs[0])  # the exponent is applied, not ignored


def test_the_logged_learning_rate_never_reads_adams_device_tensor(tiny_dataset, tmp_path, tiny_config):
    trainer = _trainer(tiny_dataset, tmp_path, tiny_config, "run", "cpu")
    _steps(trainer, 3)
    expected = float(trainer.scheduler.get_last_lr()[0])
    assert trainer.last_lr() == expected
    group = trainer.optimizer.param_groups[0]
    group["lr"] = torch.tensor(group["lr"])  # as a CUDA graph's Adam holds it
    trainer.scheduler.step()
    with count_host_syncs(trainer.device) as syncs:
        lr = trainer.last_lr()
    assert not syncs
    assert lr == pytest.approx(float(group["lr"]), rel=1e-6) and lr != expected  # the tensor is float32


def test_cuda_graphs_are_ignored_on_the_cpu(tiny_dataset, tmp_path, tiny_config):
    plain = _trainer(tiny_dataset, tmp_path, tiny_config, "plain", "cpu", "train.cuda_graphs=false", steps=8)
    graphs = _trainer(tiny_dataset, tmp_path, tiny_config, "graphs", "cpu", steps=8)  # on by default
    assert graphs.step_graphs is None
    assert _steps(plain, 8) == _steps(graphs, 8)
    for (name, a), b in zip(plain.model.state_dict().items(), graphs.model.state_dict().values(), strict=True):
        torch.testing.assert_close(a, b, rtol=0, atol=0, equal_nan=True, msg=name)


@cuda
def test_cuda_graph_steps_train_as_eager_steps(tiny_dataset, tmp_path, tiny_config):
    precision = "train.mixed_precision='off'"  # float32 on both sides: only the atomics' order may differ
    eager = _trainer(tiny_dataset, tmp_path, tiny_config, "eager", "cuda", precision, "train.cuda_graphs=false")
    graphs = _trainer(tiny_dataset, tmp_path, tiny_config, "graphs", "cuda", precision)
    assert eager.step_graphs is None
    a, b = _steps(eager, 40), _steps(graphs, 40)
    assert set(graphs.step_graphs.captured) == {(True, True), (False, True), (True, False), (False, False)}
    for step, (x, y) in enumerate(zip(a, b, strict=True)):
        assert x is not None and y is not None, step
        assert x.keys() == y.keys(), step
        # the first replays see the eager run's rays and jitter (the graph's generator offsets advance as eager
        # steps do), so only the order of atomic adds separates them; later steps drift apart a little
        rel, abs_ = (1e-4, 1e-7) if step < EAGER_STEPS + 2 else (1e-2, 1e-6)
        for term in x:
            assert math.isclose(x[term], y[term], rel_tol=rel, abs_tol=abs_), (step, term, x[term], y[term])
    for (name, p), q in zip(eager.model.named_parameters(), graphs.model.parameters(), strict=True):
        assert float((p - q).norm()) <= 1e-2 * float(p.norm()) + 1e-4, name
    # Adam read the decaying learning rate from the device tensor the scheduler fills
    assert float(graphs.optimizer.param_groups[0]["lr"]) == pytest.approx(graphs.last_lr(), rel=1e-6)
    assert graphs.last_lr() < graphs.config.train.lr


@cuda
def test_cuda_graph_replays_never_sync_and_still_skip_nonfinite_steps(tiny_dataset, tmp_path, tiny_config):
    trainer = _trainer(tiny_dataset, tmp_path, tiny_config, "run", "cuda", "train.max_nonfinite=100", steps=80)
    assert all(r is not None for r in _steps(trainer, 36))  # every branch captured by now (a capture syncs)
    assert len(trainer.step_graphs.captured) == 4
    torch.cuda.synchronize()
    torch.cuda.set_sync_debug_mode("error")
    try:
        _queue(trainer, 20)
    finally:
        torch.cuda.set_sync_debug_mode("default")
    assert all(r is not None for r in trainer.flush_steps())
    weight = next(p for p in trainer.model.field.parameters() if p.dim() > 1)
    with torch.no_grad():
        weight.fill_(float("nan"))  # the graph's finite checks are live: every later step is skipped on the device
    assert _steps(trainer, 3) == [None, None, None]


@cuda
@pytest.mark.parametrize("setting,why", [("train.compile=true", "train.compile"),
                                         ("train.mixed_precision=fp16", "fp16")])
def test_cuda_runs_that_cannot_be_captured_train_eagerly_and_say_why(tiny_dataset, tmp_path, tiny_config, capsys,
                                                                      setting, why):
    trainer = _trainer(tiny_dataset, tmp_path, tiny_config, "run", "cuda", setting)
    assert trainer.step_graphs is None
    assert why in capsys.readouterr().err


@cuda
def test_cuda_graph_training_evaluates_checkpoints_and_resumes(tiny_dataset, tmp_path, tiny_config):
    def train(steps: int, resume: bool) -> dict:
        cfg = tiny_config(tiny_dataset.root, *SCHEDULE, "train.eval_every=6", "train.checkpoint_every=6", steps=steps)
        cfg.language_targets = str(random_language_targets(tmp_path / "targets.npz", tiny_dataset.objects))
        return Trainer(cfg, tmp_path / "run", device="cuda", progress=False, resume=resume).train()

    first = train(12, resume=False)
    assert first["cuda_graphs"] and first["steps"] == 12 and math.isfinite(first["eval_psnr"])
    resumed = train(24, resume=True)  # a resumed run replays its own graphs again after its eager steps
    assert resumed["steps"] == 24 and math.isfinite(resumed["eval_psnr"])
    assert resumed["peak_reserved_mib"] >= resumed["peak_memory_mib"]
    rows = (tmp_path / "run" / "train_log.csv").read_text().splitlines()[1:]
    assert [int(r.split(",")[1]) for r in rows] == list(range(1, 25))


def test_a_step_that_cannot_be_captured_trains_on_eagerly_with_the_same_numbers(tiny_dataset, tmp_path, tiny_config,
                                                                                capsys):
    plain = _trainer(tiny_dataset, tmp_path, tiny_config, "plain", "cpu", "train.cuda_graphs=false", steps=8)
    failing = _trainer(tiny_dataset, tmp_path, tiny_config, "failing", "cpu", steps=8)
    failing.step_graphs = StepGraphs(failing)  # on the CPU no CUDA graph can be made: every capture fails
    assert _steps(plain, 8) == _steps(failing, 8)
    assert failing.step_graphs is None
    assert "eager steps from here" in capsys.readouterr().err
    group = failing.optimizer.param_groups[0]
    assert isinstance(group["lr"], float) and not group["capturable"]
    for (name, a), b in zip(plain.model.state_dict().items(), failing.model.state_dict().values(), strict=True):
        torch.testing.assert_close(a, b, rtol=0, atol=0, equal_nan=True, msg=name)


def test_a_checkpoint_of_a_graph_run_resumes_eagerly_as_if_uninterrupted(tiny_dataset, tmp_path, tiny_config):
    """A CUDA graph run saves Adam with a device-tensor lr and ``capturable``; resumed where graphs are not used
    (here the CPU, where ``capturable`` Adam refuses to step), Adam is set back to its eager form."""
    def config(steps: int):
        return tiny_config(tiny_dataset.root, "train.checkpoint_every=3", steps=steps)

    Trainer(config(6), tmp_path / "straight", device="cpu", progress=False).train()
    stopped = Trainer(config(6), tmp_path / "resumed", device="cpu", progress=False)
    original = stopped.train_step

    def step_then_stop():
        result = original()
        if stopped.step == 2:  # stopped after its third step (max_steps is part of the run: the same 6)
            stopped.request_stop("sigterm")
        return result

    stopped.train_step = step_then_stop
    stopped.train()
    path = tmp_path / "resumed" / "checkpoints" / "step_000003.pt"
    state = torch.load(path, weights_only=False)
    for group in state["optimizer"]["param_groups"]:  # as a graph run writes them
        group["lr"], group["capturable"] = torch.tensor(group["lr"]), True
    state["scheduler"]["_last_lr"] = [torch.tensor(v) for v in state["scheduler"]["_last_lr"]]
    torch.save(state, path)
    Trainer(config(6), tmp_path / "resumed", device="cpu", progress=False, resume=True).train()
    a = torch.load(tmp_path / "straight" / "model.pt", weights_only=False)["state_dict"]
    b = torch.load(tmp_path / "resumed" / "model.pt", weights_only=False)["state_dict"]
    for name in a:
        torch.testing.assert_close(a[name], b[name], rtol=0, atol=0, equal_nan=True, msg=name)
