"""Interrupted runs: `livescene train` killed midway (SIGTERM, then SIGKILL), rerun with --resume, ends with
weights bit-identical to an uninterrupted run of the same seed (CPU)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import torch

from .brief_training import TINY_MODEL, make_trainer
from .case_context import CaseContext
from .case_registry import CaseFailed, Outcome, case, require, require_module
from .tiny_scenes import hand_built_dataset

STEPS = 40
"""Long enough that the kill lands midway, short enough for the test budget."""
OVERRIDES = [*TINY_MODEL, "train.checkpoint_every=5", "train.threads=1", "train.eval_every=0"]


def _train_command(data: Path, out: Path, resume: bool = False) -> list[str]:
    # the module `livescene train` dispatches to, called directly: `python -m stages.cli` would also import every
    # other stage to list the commands (open3d alone costs seconds per start)
    cmd = [sys.executable, "-c", "from stages.model.train_cli import main; raise SystemExit(main())",
           "--data", str(data), "--out", str(out), "--device", "cpu", "--max-steps", str(STEPS), "--seed", "0",
           "--no-progress"]
    for item in OVERRIDES:
        cmd += ["--set", item]
    return [*cmd, "--resume"] if resume else cmd


def _straight_weights(ctx: CaseContext, data: Path) -> dict[str, torch.Tensor]:
    """The uninterrupted run of the same command, trained in this process (same code, same seed, 1 thread)."""

    def build() -> dict[str, torch.Tensor]:
        out = ctx.folder("interrupt-straight")
        trainer = make_trainer(data, out, steps=STEPS, overrides=OVERRIDES[len(TINY_MODEL):])
        threads = torch.get_num_threads()
        try:
            trainer.train()
        finally:
            torch.set_num_threads(threads)
        return torch.load(out / "model.pt", weights_only=True)["state_dict"]

    return ctx.cached("interrupt-straight", build)


def _kill_midway(data: Path, out: Path, sig: int, after_step: int) -> tuple[int, str]:
    """Start `livescene train`, send ``sig`` once the checkpoint of ``after_step`` exists; returns (rc, stderr)."""
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    proc = subprocess.Popen(_train_command(data, out), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=env)
    target = out / "checkpoints" / f"step_{after_step:06d}.pt"
    deadline = time.monotonic() + 120
    while not target.exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    if proc.poll() is not None:
        _, err = proc.communicate()
        raise CaseFailed(f"training ended (rc {proc.returncode}) before it could be interrupted: {err[-300:]}")
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=120)
    return proc.returncode, err


def _compare(straight: dict[str, torch.Tensor], run: Path) -> int:
    resumed = torch.load(run / "model.pt", weights_only=True)["state_dict"]
    require(resumed.keys() == straight.keys(), "resumed and uninterrupted runs have different parameters")
    differ = [k for k in straight if not torch.equal(straight[k], resumed[k])]
    require(not differ, f"resumed weights differ from the uninterrupted run in {differ[:3]}")
    return sum(v.numel() for v in straight.values())


def _resume(data: Path, out: Path) -> None:
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    done = subprocess.run(_train_command(data, out, resume=True), capture_output=True, text=True, env=env,
                          timeout=300)
    require(done.returncode == 0, f"the resumed run failed (rc {done.returncode}): {done.stderr[-300:]}")


def _published_files_complete(out: Path) -> list[str]:
    """Every published checkpoint loads (no half-written file under a real name); returns leftover temp names."""
    for p in sorted((out / "checkpoints").glob("step_*.pt")):
        try:
            torch.load(p, map_location="cpu", weights_only=False)
        except Exception as exc:
            raise CaseFailed(f"{p.name} is not a complete checkpoint after the kill ({exc})") from exc
    return sorted(p.name for p in out.rglob(".*") if p.is_file())


@case("sigterm_resume_bit_exact", "interrupted",
      "`livescene train` receiving SIGTERM midway saves a checkpoint and exits 143 without model.pt; the same "
      "command with --resume finishes with weights bit-identical to an uninterrupted run (CPU, same seed)")
def sigterm_resume_bit_exact(ctx: CaseContext) -> Outcome:
    require_module("stages.model", "model, issue 6")
    data = ctx.cached("interrupt-ds", lambda: hand_built_dataset(ctx.folder("interrupt-ds") / "ds").root)
    out = ctx.folder("interrupt-term") / "run"
    rc, err = _kill_midway(data, out, signal.SIGTERM, after_step=5)
    require(rc == 143, f"SIGTERM: exit status {rc}, expected 143; stderr: {err[-300:]}")
    require("resume" in err, f"the SIGTERM message does not say how to resume: {err[-200:]!r}")
    require(not (out / "model.pt").exists(), "an interrupted run wrote model.pt")
    saved = sorted(int(p.stem.split("_")[1]) for p in (out / "checkpoints").glob("step_*.pt"))
    require(bool(saved) and max(saved) < STEPS, f"checkpoints after SIGTERM: {saved}")
    _resume(data, out)
    n = _compare(_straight_weights(ctx, data), out)
    leftovers = _published_files_complete(out)
    require(not leftovers, f"temporary files left in the run folder: {leftovers}")
    return Outcome(f"stopped at step {max(saved)}/{STEPS}, resumed: {n} weights bit-identical to the "
                   "uninterrupted run", {"stopped_at": max(saved), "steps": STEPS, "weights": n})


@case("sigkill_resume_bit_exact", "interrupted",
      "`livescene train` killed hard (SIGKILL, no handler runs) leaves only complete checkpoints; --resume "
      "continues from the last one and ends bit-identical to an uninterrupted run")
def sigkill_resume_bit_exact(ctx: CaseContext) -> Outcome:
    require_module("stages.model", "model, issue 6")
    data = ctx.cached("interrupt-ds", lambda: hand_built_dataset(ctx.folder("interrupt-ds") / "ds").root)
    out = ctx.folder("interrupt-kill") / "run"
    rc, _ = _kill_midway(data, out, signal.SIGKILL, after_step=10)
    require(rc == -signal.SIGKILL, f"exit status {rc}, expected {-signal.SIGKILL} (killed)")
    require(not (out / "model.pt").exists(), "a killed run has model.pt")
    leftovers = _published_files_complete(out)
    saved = sorted(int(p.stem.split("_")[1]) for p in (out / "checkpoints").glob("step_*.pt"))
    _resume(data, out)
    n = _compare(_straight_weights(ctx, data), out)
    return Outcome(f"killed after step {max(saved)}/{STEPS}; resumed: {n} weights bit-identical; "
                   f"{len(leftovers)} temp files left", {"last_checkpoint": max(saved), "temp_files": leftovers})
