"""Equal-budget comparison of methods on one dataset, and parameter counts versus the number of objects.

``compare_methods`` trains every method with the same base preset, seed,
dataset, ray batch, sampler budget and wall-clock budget, each in its own
Python process (so the peak-memory figure of ``run.json``, the process's max
RSS on the CPU, belongs to that method alone), then renders the same held-out
frames from every run and scores them with the evaluation stage's PSNR and
SSIM. Per-method differences from the base preset live in
``config/model/methods/<method>.yaml`` (one overlay per preset scale), which
``load_config`` applies for every caller.

A wall-clock budget makes the step count depend on the machine's load (and the
trainer's learning-rate decay follows the spent share of the budget), so each
budgeted run records its steps and, per step, the budget fraction the schedule
saw (``time_fractions.json``); a replay retrains every method for exactly those
steps with exactly that schedule and no clock, which on the CPU reproduces the
budgeted runs bit for bit.
"""

from __future__ import annotations

import itertools
import json
import math
import subprocess
import sys
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import torch

from stages.model.config import load_config
from stages.model.methods import SceneInfo, build_model
from stages.model.methods.baselines import BASELINES
from stages.model.trainer import PendingStep, Trainer
from stages.scene import InputError, atomic_path, read_scene, write_json

ALL_METHODS = ("livescene", *BASELINES)
TABLE_COLUMNS = ["method", "psnr", "ssim", "eval_frames", "params", "field_params", "peak_memory_mib",
                 "train_seconds", "steps", "train_psnr_rays", "status"]


# -- presets ----------------------------------------------------------------------------------------------------
def method_preset(method: str, scale: str) -> dict[str, Any]:
    """The full preset (model and train sections) of ``method`` at ``scale``: base preset + method overlay."""
    cfg = load_config(scale, method=method).to_dict()
    return {"preset": cfg["preset"], "model": cfg["model"], "train": cfg["train"]}


# -- one training job (runs in a child process) -----------------------------------------------------------------
@dataclass
class TrainJob:
    """Everything a child process needs to train one method."""

    method: str
    data: str
    out: str
    preset: str = "cpu-demo"
    overrides: list[str] = field(default_factory=list)
    seed: int = 0
    device: str = "cpu"
    replay: str = ""
    """Empty: train until max_steps or the time budget. A run folder: replay its steps and schedule exactly."""


TIME_FRACTIONS = "time_fractions.json"
"""Per step, the share of the time budget the learning-rate schedule saw (written by every compare run)."""


class _ReplayableTrainer(Trainer):
    """Records the schedule's budget fraction of every step; in replay, feeds the recorded ones back and stops.

    Stopping goes through the trainer's own stop path (final eval, model.pt, run.json).
    """

    def __init__(self, *args: Any, replay: list[float] | None = None, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.replay = replay
        self.fractions: list[float] = []

    def train_step(self) -> PendingStep:
        if self.replay is not None:
            self.time_fraction = self.replay[self.step]
        self.fractions.append(float(self.time_fraction))
        result = super().train_step()
        if self.replay is not None and self.step + 1 >= len(self.replay):
            self.request_stop("step_budget")
        return result


def read_time_fractions(run_dir: str | Path) -> list[float]:
    path = Path(run_dir) / TIME_FRACTIONS
    try:
        values = json.loads(path.read_text())
        return [float(v) for v in values]
    except (OSError, ValueError, TypeError) as exc:
        raise InputError(path, f"cannot read the recorded schedule ({exc})",
                         "replay a folder written by `livescene compare`") from exc


def run_job(job: TrainJob) -> dict[str, Any]:
    """Train one method in this process; returns the run summary (run.json)."""
    config = load_config(job.preset, job.overrides, method=job.method, seed=job.seed, data=job.data)
    replay = read_time_fractions(job.replay) if job.replay else None
    if replay is not None and not replay:
        raise InputError(Path(job.replay) / TIME_FRACTIONS, "records no steps", "replay a run that trained")
    trainer = _ReplayableTrainer(config, job.out, device=job.device, progress=False, replay=replay)
    summary = trainer.train()
    write_json(Path(job.out) / TIME_FRACTIONS, trainer.fractions)
    return summary


def _train_in_child(job: TrainJob, log_path: Path) -> int:
    """Run ``run_job`` in a fresh interpreter (own RSS, own threads); stdout/stderr to ``log_path``."""
    cmd = [sys.executable, "-m", "stages.compare.method_comparison", json.dumps(job.__dict__)]
    log_path.parent.mkdir(parents=True, exist_ok=True)
    with log_path.open("w") as log:
        return subprocess.run(cmd, stdout=log, stderr=subprocess.STDOUT, check=False).returncode


# -- scoring ----------------------------------------------------------------------------------------------------
def evenly(items: Sequence[Any], n: int) -> list[Any]:
    """``n`` items spread evenly over ``items`` (all when n <= 0 or n >= len)."""
    if n <= 0 or n >= len(items):
        return list(items)
    return [items[i] for i in np.linspace(0, len(items) - 1, n).round().astype(int)]


def score_run(run_dir: Path, data: str | Path, eval_frames: int = 4, eval_scale: int = 1) -> dict[str, float | int]:
    """Mean PSNR and SSIM of renders of held-out frames (dataset 'test' split) at their states / time.

    ``eval_scale`` > 1 renders at 1/eval_scale resolution against the image
    area-downsampled to the same size (a CPU shortcut; every method gets the same). A run that refined its cameras
    (``train.camera_opt``) is scored at each view's pose aligned to it, as ``livescene evaluate`` scores it
    (docs/model.md, "Camera refinement"): its world moved off the dataset's poses.
    """
    import cv2

    from stages.evaluate.metrics import psnr, ssim
    from stages.model.run import load_run

    ds = read_scene(data)
    run = load_run(run_dir)
    index = {id(f): i for i, f in enumerate(ds.frames)}
    frames = evenly(ds.frames_in("test") or ds.frames, eval_frames)
    p, s = [], []
    for f in frames:
        cam = ds.camera_of(f)
        target = ds.load_image(f)[..., :3]
        if eval_scale > 1:
            cam = cam.scaled(1.0 / eval_scale)
            target = cv2.resize(target, (cam.width, cam.height), interpolation=cv2.INTER_AREA)
        c2w = f.c2w
        if getattr(run, "refined_cameras", False):  # seeded as the evaluation seeds it: the same pixels, the same pose
            c2w, _ = run.align_pose(cam, c2w, target, None, frame_index=index[id(f)], seed=index[id(f)])
        out = run.render(cam, c2w, None, frame_index=index[id(f)])
        p.append(psnr(out["rgb"], target))
        s.append(ssim(out["rgb"], target))
    return {"psnr": float(np.mean(p)), "ssim": float(np.mean(s)), "eval_frames": len(frames)}


# -- the comparison ---------------------------------------------------------------------------------------------
@dataclass
class CompareConfig:
    """An equal-budget comparison."""

    data: str
    """Scene dataset every method trains on."""
    out: str
    """Folder for compare.csv, compare.json and one run folder per method."""
    methods: list[str] = field(default_factory=lambda: list(ALL_METHODS))
    """Registered method names, trained in this order."""
    budget_s: float = 120.0
    """Wall-clock training budget of every method (seconds; the preset's max_steps still caps it)."""
    scale: str = "cpu-demo"
    """Base preset; each method adds its overlay from config/model/methods/<method>.yaml."""
    seed: int = 0
    """Seed of every run."""
    device: str = "cpu"
    """Training and rendering device."""
    max_steps: int = 0
    """Override of the preset's max_steps (also the length of the learning-rate schedule); 0 = preset's."""
    overrides: list[str] = field(default_factory=list)
    """Extra ``--set`` overrides applied to every method (after its overlay)."""
    eval_frames: int = 4
    """Held-out frames rendered per method for PSNR/SSIM (evenly spread over the test split; 0 = all)."""
    eval_scale: int = 1
    """Render the scored frames at 1/eval_scale resolution (targets area-downsampled alike)."""
    replay: str = ""
    """Output folder of an earlier comparison: retrain each method for its recorded steps and schedule, no clock."""
    isolate: bool = True
    """Train each method in its own process (its own max RSS); False trains in this process (tests)."""


def compare_methods(cfg: CompareConfig, progress: bool = True) -> pd.DataFrame:
    """Train and score every method; write compare.csv and compare.json atomically; return the table."""
    out = Path(cfg.out)
    out.mkdir(parents=True, exist_ok=True)
    read_scene(cfg.data)  # fail early on a bad dataset
    unknown = [m for m in cfg.methods if m not in ALL_METHODS]
    if unknown:
        raise InputError("--methods", f"unknown methods {unknown}", f"use some of {list(ALL_METHODS)}")
    rows: list[dict[str, Any]] = []
    for method in cfg.methods:
        run_dir = out / method
        if (run_dir / "checkpoints").is_dir():
            raise InputError(run_dir, "already holds a run", "choose a new --out folder")
        overrides = list(cfg.overrides)  # load_config adds the method's overlay
        replay = str(Path(cfg.replay) / method) if cfg.replay else ""
        overrides.append(f"train.max_seconds={0 if replay else cfg.budget_s}")
        if cfg.max_steps > 0:
            overrides.append(f"train.max_steps={cfg.max_steps}")
        job = TrainJob(method=method, data=str(cfg.data), out=str(run_dir), preset=cfg.scale, overrides=overrides,
                       seed=cfg.seed, device=cfg.device, replay=replay)
        if replay:
            read_time_fractions(replay)  # refuse a missing record before training anything
        t0 = time.perf_counter()
        if progress:
            what = f"the steps of {replay}" if replay else f"{cfg.budget_s:.0f} s"
            print(f"[compare] training {method} for {what} ...", file=sys.stderr, flush=True)
        if cfg.isolate:
            rc = _train_in_child(job, out / f"{method}.log")
        else:
            run_job(job)
            rc = 0
        row: dict[str, Any] = {"method": method}
        run_json = run_dir / "run.json"
        if rc != 0 or not run_json.is_file():
            row["status"] = f"failed (exit {rc}, see {method}.log)"
            rows.append(row)
            continue
        run = json.loads(run_json.read_text())
        if progress:
            print(f"[compare] {method}: {run['steps']} steps in {run['train_seconds']} s "
                  f"(+{time.perf_counter() - t0 - run['train_seconds']:.0f} s setup); scoring ...",
                  file=sys.stderr, flush=True)
        row.update(score_run(run_dir, cfg.data, cfg.eval_frames, cfg.eval_scale))
        row.update({
            "params": run["params"]["total"], "field_params": run["params"].get("field"),
            # on a GPU the allocator's reserved peak: a CUDA graph's pool is reserved, not allocated
            "peak_memory_mib": run.get("peak_reserved_mib") or run["peak_memory_mib"],
            "train_seconds": run["train_seconds"],
            "steps": run["steps"], "train_psnr_rays": run.get("eval_psnr"), "status": run["status"],
        })
        rows.append(row)
    table = pd.DataFrame(rows).reindex(columns=TABLE_COLUMNS)
    with atomic_path(out / "compare.csv", suffix=".csv") as tmp:
        table.to_csv(tmp, index=False)
    meta = {
        "data": str(cfg.data), "scale": cfg.scale, "budget_s": cfg.budget_s, "seed": cfg.seed,
        "device": cfg.device, "max_steps": cfg.max_steps, "overrides": cfg.overrides,
        "eval_frames": cfg.eval_frames, "eval_scale": cfg.eval_scale, "replay": cfg.replay or None,
        "isolated": cfg.isolate,
        "torch": torch.__version__,
        "peak_memory_kind": "process max RSS" if cfg.device == "cpu" else "cuda max_memory_reserved",
        "methods": [{k: _jsonable(v) for k, v in r.items()} for r in table.to_dict(orient="records")],
    }
    write_json(out / "compare.json", meta)
    return table


def _jsonable(v: Any) -> Any:
    if isinstance(v, float | np.floating):
        return None if math.isnan(float(v)) else float(v)
    if isinstance(v, np.integer):
        return int(v)
    return v


def format_table(table: pd.DataFrame) -> str:
    """The table as fixed-width text (what the CLI prints and docs/baselines.md quotes)."""
    shown = table.copy()
    for col, fmt in (("psnr", "{:.2f}"), ("ssim", "{:.3f}"), ("peak_memory_mib", "{:.0f}"),
                     ("train_seconds", "{:.0f}"), ("train_psnr_rays", "{:.2f}")):
        shown[col] = shown[col].map(lambda v, f=fmt: "" if v is None or pd.isna(v) else f.format(v))
    for col in ("params", "field_params", "steps", "eval_frames"):
        shown[col] = shown[col].map(lambda v: "" if v is None or pd.isna(v) else f"{int(v):,}")
    return shown.to_string(index=False)


# -- parameters versus objects ------------------------------------------------------------------------------------
def parameter_count(method: str, n_objects: int, scale: str = "cpu-demo", n_frames: int = 100) -> dict[str, int]:
    """Parameters of ``method`` for a scene of ``n_objects`` objects, by group, built on the meta device (free)."""
    cfg = load_config(scale, method=method)
    info = SceneInfo(objects=[f"object{i}" for i in range(n_objects)], n_frames=n_frames)
    with torch.device("meta"):
        model = build_model(method, cfg.model, info)
    groups = model.param_groups() if hasattr(model, "param_groups") else {}
    counts = {k: int(sum(p.numel() for p in v)) for k, v in groups.items()}
    counts["total"] = int(sum(p.numel() for p in model.parameters()))
    counts["planes_per_scale"] = len(model.field.encoding.grids[0].planes)
    return counts


def params_vs_objects(methods: Iterable[str] = ALL_METHODS, objects: Iterable[int] = range(1, 11),
                      scale: str = "cpu-demo") -> pd.DataFrame:
    """Long table: method, objects, planes per scale, field / proposal / probability / total parameters."""
    rows = []
    for method, n in itertools.product(list(methods), list(objects)):
        c = parameter_count(method, n, scale)
        rows.append({"scale": Path(scale).stem, "method": method, "objects": n,
                     "planes_per_scale": c["planes_per_scale"], "field_params": c.get("field"),
                     "proposal_params": c.get("proposal_fields"), "probability_params": c.get("probability_field"),
                     "total_params": c["total"]})
    return pd.DataFrame(rows)


if __name__ == "__main__":  # child process of compare_methods: one JSON TrainJob
    summary = run_job(TrainJob(**json.loads(sys.argv[1])))
    print(json.dumps({k: summary.get(k) for k in ("method", "status", "steps", "train_seconds", "eval_psnr")}))
