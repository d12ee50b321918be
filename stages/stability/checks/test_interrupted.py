"""Interrupted runs (group ``interrupted``): `livescene train` killed midway (SIGTERM, then SIGKILL), rerun with
--resume, ends with weights bit-identical to an uninterrupted run of the same seed (CPU); a Snakemake run of
the stage CLIs stopped midway reruns only what is incomplete. Both start real processes (marker ``slow``)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch
import yaml

from stages.scene import STAGE_MARKER, read_scene
from stages.stability.collector import Outcome

from .brief_training import TINY_MODEL, make_trainer
from .case_context import CaseContext
from .tiny_scenes import capture_spec_data, hand_built_dataset

pytestmark = [pytest.mark.stability_group("interrupted"), pytest.mark.slow]

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

    return build()


def _wait_for(proc: subprocess.Popen, path: Path, seconds: float, what: str, before: str) -> None:
    """Wait until ``path`` exists while ``proc`` runs; fail naming ``what`` ended early, with its last output."""
    deadline = time.monotonic() + seconds
    while not path.exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    if proc.poll() is not None:
        out, err = proc.communicate()
        pytest.fail(f"{what} ended (rc {proc.returncode}) before {before}: {(err or out or '')[-400:]}")


def _kill_midway(data: Path, out: Path, sig: int, after_step: int, resume: bool = False) -> tuple[int, str]:
    """Start `livescene train`, send ``sig`` once the checkpoint of ``after_step`` exists; returns (rc, stderr)."""
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    proc = subprocess.Popen(_train_command(data, out, resume), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=env)
    _wait_for(proc, out / "checkpoints" / f"step_{after_step:06d}.pt", 120, "training", "it could be interrupted")
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=120)
    return proc.returncode, err


def _compare(straight: dict[str, torch.Tensor], run: Path) -> int:
    resumed = torch.load(run / "model.pt", weights_only=True)["state_dict"]
    assert resumed.keys() == straight.keys(), "resumed and uninterrupted runs have different parameters"
    differ = [k for k in straight if not torch.equal(straight[k], resumed[k])]
    assert not differ, f"resumed weights differ from the uninterrupted run in {differ[:3]}"
    return sum(v.numel() for v in straight.values())


def _resume(data: Path, out: Path) -> None:
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    done = subprocess.run(_train_command(data, out, resume=True), capture_output=True, text=True, env=env,
                          timeout=300)
    assert done.returncode == 0, f"the resumed run failed (rc {done.returncode}): {done.stderr[-300:]}"


def _published_files_complete(out: Path) -> list[str]:
    """Every published checkpoint loads (no half-written file under a real name); returns leftover temp names."""
    for p in sorted((out / "checkpoints").glob("step_*.pt")):
        try:
            torch.load(p, map_location="cpu", weights_only=False)
        except Exception as exc:
            pytest.fail(f"{p.name} is not a complete checkpoint after the kill ({exc})")
    return sorted(p.name for p in out.rglob(".*") if p.is_file())


def test_killed_twice_resume_bit_exact(ctx: CaseContext, outcome: Outcome) -> None:
    """`livescene train` receiving SIGTERM midway saves a checkpoint and exits 143 without model.pt; rerun with
    --resume and killed hard (SIGKILL, no handler runs) later, it leaves only complete checkpoints; the third
    run resumes and ends with weights bit-identical to an uninterrupted run (CPU, same seed, no time budget)"""
    data = hand_built_dataset(ctx.folder("interrupt-ds") / "ds").root
    out = ctx.folder("interrupt-run") / "run"
    rc, err = _kill_midway(data, out, signal.SIGTERM, after_step=5)
    assert rc == 143, f"SIGTERM: exit status {rc}, expected 143; stderr: {err[-300:]}"
    assert "resume" in err, f"the SIGTERM message does not say how to resume: {err[-200:]!r}"
    assert not (out / "model.pt").exists(), "an interrupted run wrote model.pt"
    termed = sorted(int(p.stem.split("_")[1]) for p in (out / "checkpoints").glob("step_*.pt"))
    assert bool(termed) and max(termed) < STEPS, f"checkpoints after SIGTERM: {termed}"
    rc, _ = _kill_midway(data, out, signal.SIGKILL, after_step=20, resume=True)
    assert rc == -signal.SIGKILL, f"exit status {rc}, expected {-signal.SIGKILL} (killed)"
    assert not (out / "model.pt").exists(), "a killed run has model.pt"
    leftovers = _published_files_complete(out)
    killed = sorted(int(p.stem.split("_")[1]) for p in (out / "checkpoints").glob("step_*.pt"))
    _resume(data, out)
    n = _compare(_straight_weights(ctx, data), out)
    leftovers += [p for p in _published_files_complete(out) if p not in leftovers]
    outcome.record(f"SIGTERM at step {max(termed)}, SIGKILL after step {max(killed)} of {STEPS}; resumed twice: "
                   f"{n} weights bit-identical to the uninterrupted run; {len(leftovers)} temp files left",
                   {"sigterm_checkpoint": max(termed), "sigkill_checkpoint": max(killed), "weights": n,
                    "temp_files": leftovers})


SNAKEFILE = """\
# Three rules, each one call of a stage CLI (as workflow/rules/*.smk do): capture -> dataset -> train.
PY = {python!r}
rule all:
    input: "run/run.json"
rule capture:
    output: directory("capture")
    shell: PY + " -m stages.cli capture --spec spec.yaml --out {{output}} --no-progress"
rule dataset:
    input: "capture"
    output: directory("dataset")
    shell: PY + " -m stages.cli capture dataset --capture {{input}} --out {{output}} --no-progress"
rule train:
    input: "dataset"
    output: "run/run.json"
    # --resume: a rerun after an interruption continues from run/checkpoints (and starts fresh when there are none)
    shell: PY + " -c 'from stages.model.train_cli import main; raise SystemExit(main())' --data {{input}} --out run "
           "--device cpu --max-steps {steps} --resume --no-progress {overrides}"
"""


def snapshot_files(root: Path) -> dict[str, float]:
    """Modification time of every file under ``root`` by relative path (a rule that reruns rewrites them)."""
    return {str(p.relative_to(root)): p.stat().st_mtime_ns for p in root.rglob("*") if p.is_file()}


def _job_counts(dry_run_output: str) -> dict[str, int]:
    """Rule -> job count from the 'Job stats' table of `snakemake -n`."""
    counts: dict[str, int] = {}
    lines = dry_run_output.splitlines()
    start = next((i for i, s in enumerate(lines) if s.strip().startswith("Job stats")), None)
    if start is None:
        return counts
    for s in lines[start + 1 :]:
        parts = s.split()
        if len(parts) == 2 and parts[1].isdigit() and parts[0] not in ("job", "total"):
            counts[parts[0]] = int(parts[1])
        elif counts and not s.strip():
            break
    return counts


def test_snakemake_interrupt_reruns_incomplete(ctx: CaseContext, outcome: Outcome) -> None:
    """a Snakemake run of stage CLIs (capture -> dataset -> train --resume) stopped by SIGTERM during training
    leaves the finished outputs intact and no train output; `snakemake -n` then plans only the train job, and
    the rerun resumes from the last checkpoint, leaves capture and dataset untouched, and completes"""
    root = ctx.folder("snakemake-interrupt")
    spec = capture_spec_data(ctx.captures, "tiny", width=32, height=24, n_frames=6)
    (root / "spec.yaml").write_text(yaml.safe_dump(spec))
    overrides = " ".join(f"--set {item}" for item in [*TINY_MODEL, "train.threads=1", "train.checkpoint_every=5"])
    (root / "Snakefile").write_text(SNAKEFILE.format(python=sys.executable, overrides=overrides, steps=STEPS))
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    proc = subprocess.Popen([sys.executable, "-m", "snakemake", "--cores", "1", "--quiet"], cwd=root, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True)
    _wait_for(proc, root / "run" / "checkpoints" / "step_000005.pt", 240, "snakemake", "training was under way")
    os.killpg(proc.pid, signal.SIGTERM)  # what a scheduler or Ctrl-C sends to the whole job
    proc.communicate(timeout=120)
    assert proc.returncode != 0, "snakemake reported success after SIGTERM"
    ds = read_scene(root / "dataset", validate=True)
    assert not (root / "run" / "run.json").exists(), "the interrupted train rule left run/run.json"
    partial = sorted(str(p.relative_to(root)) for p in root.rglob(".*") if p.is_file()
                     and ".snakemake" not in p.parts and p.name not in (".snakemake_timestamp", STAGE_MARKER))
    assert not partial, f"temporary files left by the interrupted run: {partial[:3]}"
    plan = subprocess.run([sys.executable, "-m", "snakemake", "-n", "--cores", "1"], cwd=root, env=env,
                          capture_output=True, text=True, timeout=120)
    counts = _job_counts(plan.stdout + plan.stderr)
    assert counts.get("train") == 1 and "capture" not in counts and "dataset" not in counts, (
        f"after the interruption snakemake plans {counts or (plan.stdout + plan.stderr)[-300:]}, expected "
        "only train")
    finished = {k: v for k, v in snapshot_files(root).items() if k.startswith(("capture/", "dataset/"))}
    done = subprocess.run([sys.executable, "-m", "snakemake", "--cores", "1", "--quiet"], cwd=root, env=env,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, f"the rerun failed: {(done.stdout + done.stderr)[-400:]}"
    after = {k: v for k, v in snapshot_files(root).items() if k.startswith(("capture/", "dataset/"))}
    assert after == finished, "the rerun rewrote capture/ or dataset/ outputs"
    run = json.loads((root / "run" / "run.json").read_text())
    assert run["steps"] == STEPS, f"the rerun ended at step {run['steps']}, expected {STEPS}"
    outcome.record(f"SIGTERM during training: dataset of {len(ds.frames)} frames intact, no run.json; rerun "
                   f"planned {counts}, resumed and finished {run['steps']} steps",
                   {"planned": counts, "steps": run["steps"]})
