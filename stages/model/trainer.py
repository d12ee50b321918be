"""The shared trainer: ray batches, Adam with warm-up + cosine decay, finiteness checks, checkpoints, logs.

Every method of the registry trains here. A run folder holds::

    config.yaml              the full RunConfig (written first)
    checkpoints/step_*.pt    model, optimiser, scheduler, every RNG state, wall time so far, config, data digest
    train_log.csv            wall_s, step, lr, loss, each term, eval_psnr and eval_miou (periodic), rays_per_s
    model.pt                 final weights + what load_run needs (written last)
    exposure.json            with ``model.appearance.mode: measured``: every frame's measured log gains
    run.json                 method, parameters, peak memory, train seconds and the machine, steps, device, objects,
                             normalisation

Resuming restores the RNG states of torch, numpy, Python and both samplers'
generators, so on the CPU a resumed run is bit-identical to an uninterrupted one.
A checkpoint resumes only onto the config and data it was trained on (run_inputs.py).
"""

from __future__ import annotations

import csv
import dataclasses
import errno
import json
import math
import random
import resource
import shutil
import signal
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch
import yaml
from tqdm import tqdm

from stages.scene import InputError, SceneDataset, SceneError, atomic_path, read_scene, write_json, write_yaml
from stages.scene.atomic_io import remove_dead_temporaries
from stages.scene.exposure import read_exposure
from stages.scene.key_frame_states import frame_times, key_frame_states
from stages.scene.machine import machine_info

from .allocator import keep_freed_memory
from .appearance_choice import EXPOSURE_FILE, resolve_appearance
from .camera_opt import CameraCorrections, correction_size, exponential_factor
from .config import LossWeights, RunConfig
from .language_targets import LanguageTargets
from .methods import SceneInfo, build_model
from .ray_dataset import RayBatch, RayDataset, state_vector
from .run_inputs import TRAINING_CODE, code_digest, config_differences, data_digest, flatten_config
from .scene_normalization import SceneNormalization
from .step_graphs import GraphCaptureError, StepGraphs

MODEL_FORMAT = 2
"""2: K-Planes planes stored stacked per shape (``plane_groups.N``, was ``planes.N``)."""
# the weights of loss terms; the forms (focal_mask_on, mask_levels) and the hinge's margin are settings, not terms
LOSS_COLUMNS = [f.name for f in dataclasses.fields(LossWeights)
                if f.type in (float, "float") and f.name != "repulsion_margin"]
LOG_COLUMNS = ["wall_s", "step", "lr", "loss", *LOSS_COLUMNS, "eval_psnr", "eval_miou", "rays_per_s"]


class TrainingDiverged(RuntimeError):
    """Too many consecutive steps with a non-finite loss or gradient."""


@dataclasses.dataclass
class PendingStep:
    """A queued training step: its loss terms and finite checks, still on the device."""

    step: int
    names: list[str]
    values: torch.Tensor
    """[terms + 1]: every weighted loss term, then their sum."""
    terms_ok: torch.Tensor
    grad_names: list[str]
    grads_ok: torch.Tensor
    """[parameters with a gradient]: whether each gradient is finite."""
    wall_s: float
    lr: float


STOP_SIGNALS = tuple(getattr(signal, name) for name in ("SIGTERM", "SIGINT", "SIGHUP") if hasattr(signal, name))
"""Signals that stop a training through its normal exit with a checkpoint (docs/model.md "Run folder")."""


def resolve_device(name: str | torch.device) -> torch.device:
    name = str(name)
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name.startswith("cuda") and not torch.cuda.is_available():
        raise InputError("--device", "CUDA requested but torch sees no GPU", "use --device cpu or auto")
    try:
        return torch.device(name)
    except RuntimeError as exc:  # torch's message lists every device type it knows
        raise InputError("--device", f"{name!r} is not a device", "use --device cpu, cuda (cuda:1, ...) or auto") \
            from exc


def autocast_dtype(setting: str, device: torch.device) -> torch.dtype | None:
    """The autocast dtype of a run, or None for float32.

    'auto' is bf16 on CUDA where supported (else fp16) and off on the CPU, where
    reduced precision is slower than float32 for these small ops. 'bf16' and
    'fp16' force autocast on either device (CPU autocast runs the linear layers
    in the reduced dtype; grid sampling, volume rendering and losses stay float32).
    """
    if setting == "off":
        return None
    if setting == "auto":
        if device.type != "cuda":
            return None
        return torch.bfloat16 if torch.cuda.is_bf16_supported() else torch.float16
    if setting == "bf16":
        return torch.bfloat16
    if setting == "fp16":
        return torch.float16
    raise InputError("train.mixed_precision", f"unknown value {setting!r}", "use auto, bf16, fp16 or off")


def compile_fields(model: torch.nn.Module, mode: str = "default") -> None:
    """Compile every field's forward in place (state_dict keys unchanged); a graph break is an error.

    ``reduce-overhead`` (CUDA graphs) needs static shapes; the default mode compiles shape-generic code once.
    """
    options = {"fullgraph": True, "dynamic": mode == "default", "mode": mode}
    for name in ("field", "probability_field"):
        getattr(model, name).compile(**options)
    for proposal in getattr(model, "proposal_fields", []):
        proposal.compile(**options)


def seed_everything(seed: int) -> None:
    random.seed(seed)
    np.random.seed(seed % 2**32)
    torch.manual_seed(seed)


def scene_info(ds: SceneDataset, config: RunConfig, language: LanguageTargets | None) -> SceneInfo:
    """Objects, frame count and times, key frames (as times and states in [0, 1]) and language size of a dataset."""
    times = frame_times(ds.frames)
    key_t: list[float] = []
    key_s: list[list[float]] = []
    every = config.model.state.key_frame_every
    if every > 0:
        for i, f in enumerate(ds.frames):
            if i % every == 0:
                key_t.append(float(times[i]))
                key_s.append(state_vector(ds, f).astype(float).tolist())
    else:
        for i, values in sorted(key_frame_states(ds).by_frame.items(), key=lambda kv: ds.frames[kv[0]].frame_id):
            key_t.append(float(times[i]))
            key_s.append([float(values.get(o, math.nan)) for o in ds.objects])
    train = set(map(id, ds.frames_in("train")))
    even = len(ds.frames) < 2 or bool(np.array_equal(times, np.linspace(0.0, 1.0, len(ds.frames))))
    return SceneInfo(objects=list(ds.objects), n_frames=len(ds.frames), key_times=key_t, key_states=key_s,
                     language_dim=language.dim if language else 0,
                     language_levels=int(language.levels.numel()) if language else 0,
                     train_frames=[i for i, f in enumerate(ds.frames) if id(f) in train],
                     frame_times=None if even else [float(t) for t in times])


def lr_factor(step: int, warmup: int, total: int, final_ratio: float, time_fraction: float = 0.0) -> float:
    """Linear warm-up to 1, then cosine decay to ``final_ratio``.

    The decay's progress is the larger of the step fraction and ``time_fraction``
    (the share of a wall-clock budget already spent), so a run stopped by its
    time budget on a slow machine still ends at a low learning rate.
    """
    if warmup > 0 and step < warmup:
        if time_fraction <= 0.0:  # no budget: the warm-up alone (the same floats as ever)
            return (step + 1) / warmup
        # a budget spent within the warm-up still decays the rate (the budget's share alone drives it there)
        by_time = final_ratio + (1.0 - final_ratio) * 0.5 * (1.0 + math.cos(math.pi * min(time_fraction, 1.0)))
        return min((step + 1) / warmup, by_time)
    progress = min(max(max(step - warmup, 0) / max(total - warmup, 1), time_fraction), 1.0)
    return final_ratio + (1.0 - final_ratio) * 0.5 * (1.0 + math.cos(math.pi * progress))


def peak_memory_mib(device: torch.device) -> float:
    if device.type == "cuda":
        return torch.cuda.max_memory_allocated(device) / 2**20
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # Linux reports KiB


def psnr_of(mse: float) -> float:
    return -10.0 * math.log10(max(mse, 1e-12))


def save_atomically(obj: Any, path: Path) -> None:
    """``torch.save`` through a temporary file renamed onto ``path``. Saved to a file object, the archive's records
    are named "archive/..." rather than after the temporary file, so identical runs write identical bytes."""
    with atomic_path(path, suffix=".pt") as tmp, tmp.open("wb") as fh:
        try:
            torch.save(obj, fh)
        except RuntimeError as exc:  # torch's archive writer reports a full disk as "unexpected pos ..."
            if shutil.disk_usage(path.parent).free < 64 * 2**20:
                raise OSError(errno.ENOSPC, "no space left on the device", str(path)) from exc
            raise


class Trainer:
    """Trains one method on one scene dataset into a run folder."""

    def __init__(self, config: RunConfig, out_dir: str | Path, device: str = "auto", resume: bool = False,
                 progress: bool = True, restart_stale: bool = False) -> None:
        self.config = config
        self.out = Path(out_dir)
        self.device = resolve_device(device)
        self.resume = resume
        self.restart_stale = restart_stale
        """With ``resume``: a checkpoint of other inputs is discarded and training starts over (else an error)."""
        self.progress = progress
        self._stop_reason: str | None = None
        self.stop_signal: int | None = None
        """The signal that stopped the run (SIGTERM, SIGINT, SIGHUP), None when none did."""
        self.amp_dtype = autocast_dtype(config.train.mixed_precision, self.device)
        self._setup()

    # -- setup ----------------------------------------------------------------------------------------------
    def _auto_state_mode(self) -> str:
        """``given`` when every frame carries every object's state (a dataset of this project's states stage);
        ``learned`` when only key frames give states, as in the published datasets, which the reference trains
        from their key frames alone; else ``given``, whose error names the missing states."""
        ds = self.ds
        if not ds.objects or all(f.state and set(ds.objects) <= set(f.state) for f in ds.frames):
            return "given"
        if ds.key_frames:
            print(f"{ds.root}: states only at key frames ({ds.root / 'key_frame_value.yaml'}): state mode learned",
                  file=sys.stderr)
            return "learned"
        return "given"

    def _setup(self) -> None:
        cfg = self.config
        if cfg.train.threads > 0:
            torch.set_num_threads(cfg.train.threads)
        keep_freed_memory()
        if not cfg.data:
            raise InputError("--data", "no dataset given", "pass --data DS (a scene dataset folder)")
        self.ds = read_scene(cfg.data)
        measured = None
        if cfg.exposure and cfg.model.appearance.mode in ("auto", "measured"):
            measured = read_exposure(cfg.exposure, self.ds)
        elif cfg.exposure:
            print(f"{cfg.exposure}: not read, model.appearance.mode is {cfg.model.appearance.mode}", file=sys.stderr)
        self.appearance = resolve_appearance(cfg.model.appearance, self.ds, measured)
        if "requested" in self.appearance:
            print(f"appearance auto: {self.appearance['reason']}: {self.appearance['mode']}", file=sys.stderr)
        mode = cfg.model.state.mode
        if mode not in ("auto", "given", "learned"):
            raise InputError("--state-mode", f"unknown state mode {mode!r}", "use auto, given or learned")
        if self.ds.split_note:
            print(f"{self.ds.root}: transforms.json names no split: {self.ds.split_note}", file=sys.stderr)
        if mode == "auto":  # the resolved mode is what the run's config records
            mode = cfg.model.state.mode = self._auto_state_mode()
        if mode == "learned" and not self.ds.objects:
            # a room filmed without masks or key frames has no object whose state could be learned: it trains as
            # a static field (the resolved mode is what the run's config records, as with appearance auto)
            print(f"{self.ds.root}: no objects, so no states to learn: state mode given", file=sys.stderr)
            mode = cfg.model.state.mode = "given"
        self.language = LanguageTargets.read(cfg.language_targets, self.ds.objects) if cfg.language_targets else None
        seed_everything(cfg.seed)
        self.norm = SceneNormalization.from_dataset(self.ds)
        train_frames, held_out = self.ds.frames_in("train"), self.ds.frames_in("test")
        if not train_frames and held_out:  # the evaluation would call trained views held out
            raise SceneError(self.ds.root / "transforms.json", f"all {len(held_out)} split frames are test frames, "
                             "so training would use the views the evaluation holds out",
                             'mark the training frames "split": "train" (or drop the split keys to train on every '
                             "frame without a held-out evaluation)")
        train_frames = train_frames or self.ds.frames
        test_frames = held_out or train_frames
        near = cfg.model.sampling.near_plane
        # learned-state mode: rays carry no states, so training AND the periodic evaluation use the learned ones
        given = mode == "given"
        # measured gains shape the training colours; the evaluation reads them from exposure.json for a held-out
        # PSNR at the nominal exposure, beside the one against the images as they are
        self.log_gains: dict[str, list[float]] | None = self.appearance.pop("log_gains", None)
        self.train_rays = RayDataset(self.ds, train_frames, self.norm, near, self.device, need_states=given,
                                     log_gains=self.log_gains)
        self.eval_rays = RayDataset(self.ds, test_frames, self.norm, near, self.device, need_states=given)
        self.info = scene_info(self.ds, cfg, self.language)
        self.key_frame_ranges = key_frame_states(self.ds).rescaled if mode == "learned" else {}
        kpath = self.ds.root / "key_frame_value.yaml"
        for name, r in self.key_frame_ranges.items():
            print(f"{kpath}: {name!r} key values {r['lo']:g}..{r['hi']:g} mapped to [0, 1] ({r['source']})",
                  file=sys.stderr)
        self.data_digest = data_digest(self._data_tensors())
        if mode == "learned" and not self.info.key_times:
            raise InputError(self.ds.root / "key_frame_value.yaml", "learned-state mode needs key frames, found none",
                             "annotate key frames, or set --set model.state.key_frame_every=N")
        self.model = build_model(cfg.method, cfg.model, self.info).to(self.device)
        if self.ds.n_objects and self.model.field_reads_probabilities and not bool((self.train_rays.labels >= 0).any()):
            # only the mask losses train the probability field, which places every sample's state (docs/method.md 2)
            raise SceneError(self.ds.root / "masks", f"the dataset names objects {self.ds.objects} but no training "
                             f"frame has a mask: {cfg.method}'s probability field, which decides what each object's "
                             "state moves, would learn nothing", "ingest masks (`livescene labels`, then `livescene "
                             "dataset assemble --labels`), or train a method that reads every state everywhere "
                             "(--method mk-planes)")
        if cfg.train.compile:
            compile_fields(self.model, cfg.train.compile_mode)
        # compiled fields' CUDA graph replays overwrite their last outputs: each step starts a new generation of them
        self._compiled_graphs = cfg.train.compile and cfg.train.compile_mode == "reduce-overhead" \
            and self.device.type == "cuda"
        self.step_graphs = None
        self.cameras = self._camera_corrections() if cfg.train.camera_opt != "off" else None
        if cfg.train.cuda_graphs and self.device.type == "cuda":
            # compiled fields bring their own graphs; fp16's loss scaler decides on the host at every step; the
            # corrections' own Adam and schedule are not part of a captured step
            eager_why = "train.compile is on" if cfg.train.compile else \
                "fp16 autocast scales the loss" if self.amp_dtype == torch.float16 else \
                "train.camera_opt is on (the captured step holds no camera corrections)" if self.cameras else ""
            if eager_why:
                print(f"train.cuda_graphs: eager steps, since {eager_why}", file=sys.stderr)
            else:
                self.step_graphs = StepGraphs(self)
        if self.language is not None:
            self.language = self.language.to(self.device)
        self._named_params = [(n, p) for n, p in self.model.named_parameters() if p.requires_grad]
        # every parameter whose gradient the step's finite check reads: the model's, then the camera corrections'
        self._checked_params = self._named_params + ([("camera_opt.adjustment", self.cameras.adjustment)]
                                                     if self.cameras is not None else [])
        # fused Adam takes the step's finite check as a device tensor (found_inf) and skips the update on the
        # device: no host sync decides whether a step counts
        self.optimizer = torch.optim.Adam([p for _, p in self._named_params], lr=cfg.train.lr,
                                          eps=cfg.train.adam_eps, fused=True)
        t = cfg.train
        self.time_fraction = 0.0  # share of train.max_seconds spent (0 without a budget); drives the decay too
        self.scheduler = torch.optim.lr_scheduler.LambdaLR(
            self.optimizer, lambda s: lr_factor(s, t.warmup_steps, t.max_steps, t.lr_final_ratio, self.time_fraction))
        self.camera_optimizer = self.camera_scheduler = None
        if self.cameras is not None:  # its own Adam and exponential decay (docs/model.md, "Camera refinement")
            self.camera_optimizer = torch.optim.Adam(self.cameras.parameters(), lr=t.camera_opt_lr, eps=1e-15,
                                                     fused=True)
            self.camera_scheduler = torch.optim.lr_scheduler.LambdaLR(
                self.camera_optimizer, lambda s: exponential_factor(s, t.max_steps, t.camera_opt_lr_final
                                                                    / t.camera_opt_lr, self.time_fraction))
        # fp16 has too few exponent bits for small gradients: scale the loss (bf16 needs no scaler)
        self.scaler = torch.amp.GradScaler(self.device.type) if self.amp_dtype == torch.float16 else None
        self.ray_generator = torch.Generator().manual_seed(cfg.seed)
        self.jitter_generator = torch.Generator(device=self.device).manual_seed(cfg.seed + 1)
        eval_gen = torch.Generator().manual_seed(cfg.seed + 2)
        n_eval = min(cfg.train.eval_rays, self.eval_rays.n_rays)
        self.eval_index = torch.randperm(self.eval_rays.n_rays, generator=eval_gen)[:n_eval]
        self.step = 0
        self.wall_before = 0.0
        self.nonfinite_streak = 0
        self._pending: list[PendingStep] = []
        self._t0 = time.perf_counter()
        self.log_rows: list[dict[str, Any]] = []
        self.last_eval_miou: float | None = None

    def _camera_corrections(self) -> CameraCorrections:
        """A zero correction per training frame (``train.camera_opt``), looked up by the rays' dataset frame index."""
        rows = torch.full((len(self.ds.frames),), -1, dtype=torch.long)
        rows[self.train_rays.frame_index.cpu()] = torch.arange(len(self.train_rays.frames))
        return CameraCorrections(rows, len(self.train_rays.frames)).to(self.device)

    def camera_summary(self) -> dict[str, Any] | None:
        """run.json's account of the refined cameras: the mode and the corrections' sizes (None when off)."""
        if self.cameras is None:
            return None
        sizes = [correction_size(a, self.norm) for a in self.cameras.adjustment.detach().cpu().double().numpy()]
        rot = [s["rotation_deg"] for s in sizes]
        trans = [s["translation"] for s in sizes]
        return {"mode": self.config.train.camera_opt, "frames": len(sizes),
                "rotation_deg": {"mean": float(np.mean(rot)), "max": float(np.max(rot))},
                "translation": {"mean": float(np.mean(trans)), "max": float(np.max(trans)),
                                "unit": "dataset units"}}

    def camera_payload(self) -> dict[str, Any]:
        """model.pt's record of the refined cameras (what the evaluation's pose alignment reads)."""
        return {"mode": self.config.train.camera_opt,
                "frame_ids": [f.frame_id for f in self.train_rays.frames],
                "adjustment": self.cameras.adjustment.detach().cpu().clone()}

    def _data_tensors(self) -> dict[str, Any]:
        """Everything of the dataset that training reads, as tensors: the checkpoint's data digest covers these."""
        out: dict[str, Any] = {}
        for split, rays in (("train", self.train_rays), ("eval", self.eval_rays)):
            for name in ("images", "labels", "states", "times", "rotations", "centres", "shared_dirs", "cam_dirs",
                         "frame_index"):
                out[f"{split}.{name}"] = getattr(rays, name)
        if self.language is not None:
            for name in ("levels", "embeddings", "background"):
                out[f"language.{name}"] = getattr(self.language, name)
        out["objects"] = np.array(list(self.info.objects), dtype=str)
        out["key_times"] = np.asarray(self.info.key_times, dtype=np.float64)
        out["key_states"] = np.asarray(self.info.key_states, dtype=np.float64)
        return out

    # -- checkpoints ----------------------------------------------------------------------------------------
    def checkpoint_path(self, step: int) -> Path:
        return self.out / "checkpoints" / f"step_{step:06d}.pt"

    def latest_checkpoint(self) -> Path | None:
        found = sorted((self.out / "checkpoints").glob("step_*.pt"))
        return found[-1] if found else None

    def save_checkpoint(self, wall_s: float) -> Path:
        if not all(bool(torch.isfinite(p).all()) for p in self.model.parameters()):
            raise TrainingDiverged(f"parameters are not finite at step {self.step}; no checkpoint written")
        state = {
            "step": self.step,
            "wall_s": wall_s,
            "nonfinite_streak": self.nonfinite_streak,
            "model": self.model.state_dict(),
            "optimizer": self.optimizer.state_dict(),
            "scheduler": self.scheduler.state_dict(),
            "scaler": self.scaler.state_dict() if self.scaler else None,
            "rng": {
                "torch": torch.get_rng_state(),
                "cuda": torch.cuda.get_rng_state_all() if torch.cuda.is_available() else None,
                "numpy": np.random.get_state(),
                "python": random.getstate(),
                "rays": self.ray_generator.get_state(),
                "jitter": self.jitter_generator.get_state(),
            },
            "config": self.config.to_dict(),
            "data_digest": self.data_digest,
            "code_digest": code_digest(),
            "device_type": self.device.type,  # whose generator the jitter state is
        }
        if self.cameras is not None:
            state["camera_opt"] = {"corrections": self.cameras.state_dict(),
                                   "optimizer": self.camera_optimizer.state_dict(),
                                   "scheduler": self.camera_scheduler.state_dict()}
        path = self.checkpoint_path(self.step)
        save_atomically(state, path)
        kept = sorted((self.out / "checkpoints").glob("step_*.pt"))
        for old in kept[: max(len(kept) - max(self.config.train.keep_checkpoints, 1), 0)]:
            old.unlink(missing_ok=True)
        return path

    def stale_reason(self, state: dict[str, Any]) -> str:
        """Why a checkpoint belongs to other inputs than this run's ('' when it continues this run)."""
        reasons = []
        if state.get("data_digest") is None:
            reasons.append("it records no data digest (written by an older livescene), so its data cannot be checked")
        elif state["data_digest"] != self.data_digest:
            reasons.append(f"its training data differ from {self.config.data} (poses, images, masks, states or "
                           "language targets changed)")
        if state.get("code_digest") is None:
            reasons.append("it records no code digest (written by an older livescene), so the code that trained it "
                           "cannot be checked")
        elif state["code_digest"] != code_digest():
            reasons.append(f"it was trained by other code (stages/{' or stages/'.join(TRAINING_CODE)} changed since, "
                           "or torch's version)")
        changed = config_differences(state.get("config", {}), self.config.to_dict())
        if changed:
            was, now = flatten_config(state.get("config", {})), flatten_config(self.config.to_dict())
            shown = ", ".join(f"{k} ({was.get(k, 'absent')!r} there, {now.get(k, 'absent')!r} now)"
                              for k in changed[:6]) + (f" and {len(changed) - 6} more" if len(changed) > 6 else "")
            reasons.append(f"its config differs in {shown}")
        return "; ".join(reasons)

    def discard_checkpoints(self, why: str) -> None:
        """Remove a stale run's checkpoints and log (model.pt and run.json are rewritten at the end)."""
        for old in sorted((self.out / "checkpoints").glob("step_*.pt")):
            old.unlink()
        self.finished_record.unlink(missing_ok=True)
        (self.out / "train_log.csv").unlink(missing_ok=True)
        print(f"{self.out}: starting over, the checkpoints there were of another run: {why}", file=sys.stderr)

    def resume_from(self, path: Path) -> None:
        """Continue from ``path`` if it holds this run; a stale one is discarded (``restart_stale``) or refused."""
        state = torch.load(path, map_location=self.device, weights_only=False)
        why = self.stale_reason(state)
        if not why:
            self.load_checkpoint(state)
            if self.step < self.config.train.max_steps:  # a finished run says "nothing to train" instead
                print(f"{self.out}: resumed from {path.name} at step {self.step}", file=sys.stderr)
        elif self.restart_stale:
            self.discard_checkpoints(why)
        else:
            raise InputError(path, f"cannot resume: {why}",
                             "resume with the inputs and config it was trained on, write this run to a new --out, "
                             "or pass --restart-stale to discard those checkpoints and train from step 0")

    def load_checkpoint(self, state: dict[str, Any]) -> None:
        self.model.load_state_dict(state["model"])
        self.optimizer.load_state_dict(state["optimizer"])
        self.scheduler.load_state_dict(state["scheduler"])
        for group in self.optimizer.param_groups:
            # a CUDA graph run saves Adam capturable with a float32 device-tensor lr: resume in the eager form, at
            # the schedule's exact value (a capture converts again)
            group["capturable"], group["lr"] = False, self.last_lr()
        if self.cameras is not None:  # a checkpoint without them is of another config: stale_reason refused it
            self.cameras.load_state_dict(state["camera_opt"]["corrections"])
            self.camera_optimizer.load_state_dict(state["camera_opt"]["optimizer"])
            self.camera_scheduler.load_state_dict(state["camera_opt"]["scheduler"])
        if self.scaler is not None and state.get("scaler"):
            self.scaler.load_state_dict(state["scaler"])
        # generator states are CPU byte tensors, whatever the generator's device; a checkpoint loaded onto CUDA
        # (map_location) holds them there
        rng = {k: v.cpu() if isinstance(v, torch.Tensor) else v for k, v in state["rng"].items()}
        torch.set_rng_state(rng["torch"])
        if rng.get("cuda") is not None and torch.cuda.is_available():
            for i, cuda_state in enumerate(rng["cuda"][: torch.cuda.device_count()]):
                torch.cuda.set_rng_state(cuda_state.cpu(), i)
        np.random.set_state(rng["numpy"])
        random.setstate(rng["python"])
        self.ray_generator.set_state(rng["rays"])  # a CPU generator on every device
        written_on = state.get("device_type", self.device.type)  # older checkpoints: taken as this device's
        if written_on == self.device.type:
            self.jitter_generator.set_state(rng["jitter"])
        else:
            # a CPU generator's state (Mersenne Twister) does not fit a CUDA one (Philox seed and offset) or back
            self.jitter_generator.manual_seed(self.config.seed + 1 + int(state["step"]))
            print(f"{self.out}: the checkpoint was written on {written_on}, training goes on on {self.device.type} "
                  "with the sample jitter reseeded: a run repeats an uninterrupted one only on the device it began on",
                  file=sys.stderr)
        self.step = int(state["step"])
        self.wall_before = float(state["wall_s"])
        self.nonfinite_streak = int(state.get("nonfinite_streak", 0))
        log = self.out / "train_log.csv"
        if log.is_file():
            with log.open() as fh:
                self.log_rows = [r for r in csv.DictReader(fh) if int(float(r["step"])) <= self.step]

    # -- one step -------------------------------------------------------------------------------------------
    def _autocast(self, cache_casts: bool = True) -> Any:
        if self.amp_dtype is None:
            return torch.autocast(device_type=self.device.type, enabled=False)
        # a CUDA graph must not keep the casts of weights cached at capture (torch's CUDA graph notes)
        return torch.autocast(device_type=self.device.type, dtype=self.amp_dtype, cache_enabled=cache_casts)

    def step_body(self, batch: RayBatch, step: int, anneal: float | torch.Tensor | None = None,
                  cache_casts: bool = True) -> tuple[list[str], torch.Tensor, torch.Tensor, list[str], torch.Tensor]:
        """Forward, loss terms, backward, finite checks and Adam's update, all queued on the device.

        Returns the term names, every weighted term and their sum, the terms' finite flags, the names of the
        parameters with a gradient and those gradients' finite flags. A step with a non-finite term or gradient
        is skipped on the device (fused Adam's ``found_inf`` leaves weights, moments and step count as they
        were). Eager steps and CUDA graph captures (step_graphs.py) run this same code.
        """
        rays = batch.rays
        if self.cameras is not None:  # each ray moved by its training frame's correction (float32, before autocast)
            rays = self.cameras.correct(rays, batch.frames, self.config.model.sampling.near_plane)
        with self._autocast(cache_casts):
            out = self.model(rays, step=step, generator=self.jitter_generator, anneal=anneal)
            terms = self.model.loss_dict(out, batch, step, self.language)
        if self.cameras is not None:  # a term of the sum, not a column of train_log.csv
            t = self.config.train
            terms["camera_opt"] = self.cameras.penalty(t.camera_opt_translation_penalty, t.camera_opt_rotation_penalty)
        names = list(terms)
        values = torch.stack([terms[n].float() for n in names])
        terms_ok = torch.isfinite(values)
        self.optimizer.zero_grad(set_to_none=True)
        if self.camera_optimizer is not None:
            self.camera_optimizer.zero_grad(set_to_none=True)
        loss = values.sum()
        if self.scaler is not None:
            self.scaler.scale(loss).backward()
            self.scaler.unscale_(self.optimizer)
            if self.camera_optimizer is not None:
                self.scaler.unscale_(self.camera_optimizer)
        else:
            loss.backward()
        with_grad = [(n, p) for n, p in self._checked_params if p.grad is not None]
        grads_ok = torch.isfinite(torch.stack(torch._foreach_norm([p.grad for _, p in with_grad]))) if with_grad \
            else terms_ok[:0]
        bad = ~(terms_ok.all() & grads_ok.all())
        self.optimizer.found_inf = bad.float()
        self.optimizer.step()
        if self.camera_optimizer is not None:  # skipped on the device with the model's step
            self.camera_optimizer.found_inf = self.optimizer.found_inf
            self.camera_optimizer.step()
        return names, torch.cat([values.detach(), loss.detach()[None]]), terms_ok, [n for n, _ in with_grad], grads_ok

    def train_step(self) -> PendingStep:
        """One optimisation step, queued without waiting for the device.

        Nothing is read back to the host: ``flush_steps`` reads every queued
        step at once, names the skipped ones and keeps the streak (docs/model.md).
        With ``train.cuda_graphs`` on CUDA the step is a graph replay after a few eager steps.
        """
        self.model.train()
        if self._compiled_graphs:
            torch.compiler.cudagraph_mark_step_begin()
        # the rays ``RayDataset.sample`` draws, the same for a replayed step and an eager one
        n = self.config.train.batch_rays
        indices = torch.randint(0, self.train_rays.n_rays, (n,), generator=self.ray_generator)
        replayed = None
        if self.step_graphs is not None and self.step_graphs.ready():
            try:
                replayed = self.step_graphs.run(self.step, indices)
            except GraphCaptureError as exc:
                print(f"train.cuda_graphs: {exc}; eager steps from here (train.cuda_graphs=false skips the attempt)",
                      file=sys.stderr)
                self.step_graphs = None
        if replayed is not None:
            names, values, terms_ok, grad_names, grads_ok = replayed
        else:
            batch = self.train_rays.batch(indices)
            names, values, terms_ok, grad_names, grads_ok = self.step_body(batch, self.step)
            if self.scaler is not None:
                self.scaler.update()  # lowers the loss scale after an overflow (recorded by unscale_)
            if self.step_graphs is not None:
                self.step_graphs.eager_step_done()
        self.scheduler.step()
        if self.camera_scheduler is not None:
            self.camera_scheduler.step()
        pending = PendingStep(self.step, names, values, terms_ok, grad_names, grads_ok,
                              self.wall_before + time.perf_counter() - self._t0, self.last_lr())
        self._pending.append(pending)
        return pending

    def last_lr(self) -> float:
        """The learning rate of the next step, without reading the device."""
        lr = self.scheduler.get_last_lr()[0]
        if isinstance(lr, torch.Tensor):  # a CUDA graph's: Adam reads it on the device; the value is the schedule's
            lr = self.scheduler.base_lrs[0] * self.scheduler.lr_lambdas[0](self.scheduler.last_epoch)
        return float(lr)

    def flush_steps(self) -> list[dict[str, float] | None]:
        """Read every queued step from the device (one sync); their loss terms, or None for a skipped step.

        Skipped steps are named on stderr with the terms or parameters that were
        not finite; ``train.max_nonfinite`` skipped steps in a row stop training.
        """
        pending, self._pending = self._pending, []
        if not pending:
            return []
        # one transfer for the whole queue: per step its values, then its term and gradient flags
        flat = torch.cat([torch.cat([p.values, p.terms_ok.float(), p.grads_ok.float()]) for p in pending])
        flat = flat.cpu().tolist()
        results: list[dict[str, float] | None] = []
        diverged: str | None = None
        at = 0
        for p in pending:
            n_v, n_t, n_g = len(p.values), len(p.names), len(p.grad_names)
            vals = flat[at : at + n_v]
            terms_ok, grads_ok = flat[at + n_v : at + n_v + n_t], flat[at + n_v + n_t : at + n_v + n_t + n_g]
            at += n_v + n_t + n_g
            if all(terms_ok) and all(grads_ok):
                self.nonfinite_streak = 0
                result = dict(zip(p.names, vals[:-1], strict=True))
                result["loss"] = vals[-1]
                results.append(result)
                self.log_rows.append({"wall_s": round(p.wall_s, 3), "step": p.step + 1, "lr": p.lr,
                                      "eval_psnr": None, "eval_miou": None, **result})
                continue
            bad_terms = [n for n, ok in zip(p.names, terms_ok, strict=True) if not ok]
            bad_grads = [n for n, ok in zip(p.grad_names, grads_ok, strict=True) if not ok]
            why = (f"non-finite loss term(s) {bad_terms}" if bad_terms else
                   f"non-finite gradient in {', '.join(bad_grads[:3])}" + (" ..." if len(bad_grads) > 3 else ""))
            self.nonfinite_streak += 1
            results.append(None)
            tqdm.write(f"step {p.step}: skipped ({why}); {self.nonfinite_streak} in a row", file=sys.stderr)
            if diverged is None and self.nonfinite_streak >= self.config.train.max_nonfinite:
                diverged = (f"{self.nonfinite_streak} consecutive steps with {why} (steps "
                            f"{p.step - self.nonfinite_streak + 1}-{p.step})")
        if diverged is not None:
            # the flags are read once per log interval (no sync per step), so the steps queued after the limit
            # ran too: the message names the last one, where training really stopped
            raise TrainingDiverged(f"{diverged}; training stopped after step {pending[-1].step} (the steps' "
                                   "finite flags are read once per log interval) without saving (the last "
                                   "checkpoint is the last finite state)")
        return results

    @torch.no_grad()
    def evaluate(self) -> float:
        """PSNR of the fixed held-out rays (also sets ``last_eval_miou``, the mask IoU of those rays)."""
        self.model.eval()
        chunk = self.config.train.render_chunk
        err, n = 0.0, 0
        alpha = self.info.n_objects
        inter = torch.zeros(alpha)
        union = torch.zeros(alpha)
        for i in range(0, len(self.eval_index), chunk):
            batch = self.eval_rays.batch(self.eval_index[i : i + chunk])
            with self._autocast():
                out = self.model(batch.rays, step=self.step, outputs=("rgb", "logits"))
            err += float((out["rgb"].float().clamp(0, 1) - batch.rgb).square().sum())
            n += batch.rgb.numel()
            if alpha and "logits" in out:
                valid = batch.labels >= 0
                pred, gt = out.get("probs", out["logits"]).argmax(-1)[valid].cpu(), batch.labels[valid].cpu()
                for c in range(alpha):
                    inter[c] += float(((pred == c) & (gt == c)).sum())
                    union[c] += float(((pred == c) | (gt == c)).sum())
        self.model.train()
        seen = union > 0
        self.last_eval_miou = float((inter[seen] / union[seen]).mean()) if bool(seen.any()) else None
        return psnr_of(err / max(n, 1))

    # -- the loop -------------------------------------------------------------------------------------------
    def request_stop(self, reason: str) -> None:
        """Stop before the next step through the normal exit (final eval, checkpoint, model.pt, run.json).

        ``reason`` becomes run.json's status; "sigterm" is special: the run is left resumable, without model.pt.
        """
        self._stop_reason = reason

    def _on_signal(self, signum: int, frame: Any) -> None:
        """SIGTERM (a scheduler), SIGINT (Ctrl-C) and SIGHUP (a closed terminal) alike: stop before the next step,
        save a checkpoint and leave the run resumable (run.json status "sigterm", whichever signal it was)."""
        self.stop_signal = signum
        self.request_stop("sigterm")

    def _write_log(self) -> None:
        with atomic_path(self.out / "train_log.csv", suffix=".csv") as tmp, tmp.open("w", newline="") as fh:
            writer = csv.DictWriter(fh, fieldnames=LOG_COLUMNS, extrasaction="ignore")
            writer.writeheader()
            writer.writerows(self.log_rows)

    def train(self) -> dict[str, Any]:
        cfg = self.config
        self.out.mkdir(parents=True, exist_ok=True)
        remove_dead_temporaries(self.out / "checkpoints")  # a checkpoint a killed run was half way through saving
        if self.resume:
            ckpt = self.latest_checkpoint()
            if ckpt is not None:
                self.resume_from(ckpt)
        elif (self.out / "checkpoints").is_dir() and any((self.out / "checkpoints").glob("step_*.pt")):
            raise InputError(self.out, "already holds checkpoints of a run",
                             "pass --resume to continue it, or choose a new --out folder")
        if self.step >= cfg.train.max_steps and self.finished_record.is_file() and (self.out / "model.pt").is_file():
            return self._already_finished(cfg)
        write_yaml(self.out / "config.yaml", cfg.to_dict())
        handlers = {}
        try:  # held until the run's last checkpoint is written: a second signal during the save changes nothing
            for sig in STOP_SIGNALS:
                handlers[sig] = signal.signal(sig, self._on_signal)
        except ValueError:  # not the main thread: no signal handling
            pass
        try:
            return self._train(cfg)
        finally:
            for sig, handler in handlers.items():
                signal.signal(sig, handler)

    @property
    def finished_record(self) -> Path:
        """run.json's copy beside the checkpoints: a workflow rerun finds run.json itself deleted (Snakemake removes
        a job's outputs before it runs), and the training's figures must outlive that."""
        return self.out / "checkpoints" / "run.json"

    def _already_finished(self, cfg: RunConfig) -> dict[str, Any]:
        """A finished run resumed with nothing left to train (a rerun after a setting of how it runs changed, such
        as a trust floor): its weights, log and records stay those of the training; config.yaml takes the new trust
        floors, which judge it, and run.json is written again unchanged (a rerun job's output is new)."""
        run = json.loads(self.finished_record.read_text())
        trained = yaml.safe_load((self.out / "config.yaml").read_text()) if (self.out / "config.yaml").is_file() \
            else cfg.to_dict()
        trained["trust"] = cfg.to_dict()["trust"]
        write_yaml(self.out / "config.yaml", trained)
        write_json(self.out / "run.json", run)
        print(f"{self.out}: finished at step {self.step}: nothing to train, its model.pt and run.json kept",
              file=sys.stderr)
        return run

    def _train(self, cfg: RunConfig) -> dict[str, Any]:
        if self.step < cfg.train.max_steps:
            # a run trained again (or a time-budget run resumed) is unfinished until it is done: run.json (the
            # completion mark, first) and model.pt go, or an interruption would leave old weights looking final
            for path in (self.out / "run.json", self.finished_record, self.out / "model.pt"):
                path.unlink(missing_ok=True)
        if self.device.type == "cuda":
            torch.cuda.reset_peak_memory_stats(self.device)
        t0 = self._t0 = time.perf_counter()
        max_seconds = cfg.train.max_seconds
        bar = tqdm(total=cfg.train.max_steps, initial=self.step, unit="step", disable=not self.progress,
                   dynamic_ncols=True, desc=f"train {cfg.method}")
        last_psnr: float | None = None
        window = [time.perf_counter(), self.step]
        status = "completed"

        def read_back() -> None:
            """The one sync of a logging interval: queued steps -> log rows, skip messages, progress bar."""
            results = self.flush_steps()
            now = time.perf_counter()
            rays_per_s = (self.step - window[1]) * cfg.train.batch_rays / max(now - window[0], 1e-9)
            window[:] = [now, self.step]
            for row in self.log_rows[len(self.log_rows) - sum(r is not None for r in results):]:
                row["rays_per_s"] = round(rays_per_s, 1)
            done = [r for r in results if r is not None]
            if not results:  # nothing ran since the last read (the loop's final read): the bar keeps its figures
                return
            post = {"loss": f"{done[-1]['loss']:.4f}" if done else "skipped", "rays/s": f"{rays_per_s:.0f}"}
            if last_psnr is not None:
                post["psnr"] = f"{last_psnr:.2f}"
            if max_seconds > 0:
                post["left_s"] = f"{max(max_seconds - (self.wall_before + now - t0), 0):.0f}"
            bar.set_postfix(post, refresh=False)

        try:
            while self.step < cfg.train.max_steps:
                elapsed = self.wall_before + time.perf_counter() - t0
                if max_seconds > 0 and elapsed >= max_seconds:
                    status = "time_budget"
                    break
                if self._stop_reason:
                    status = self._stop_reason
                    break
                self.time_fraction = elapsed / max_seconds if max_seconds > 0 else 0.0
                self.train_step()
                self.step += 1
                bar.update(1)
                is_eval = cfg.train.eval_every > 0 and (self.step % cfg.train.eval_every == 0
                                                        or self.step == cfg.train.max_steps)
                is_checkpoint = cfg.train.checkpoint_every > 0 and self.step % cfg.train.checkpoint_every == 0
                if is_eval or is_checkpoint or self.step % max(cfg.train.log_every, 1) == 0:
                    read_back()
                if is_eval:
                    last_psnr = self.evaluate()
                    if self.log_rows and int(self.log_rows[-1]["step"]) == self.step:
                        self.log_rows[-1]["eval_psnr"] = last_psnr
                        self.log_rows[-1]["eval_miou"] = self.last_eval_miou
                    self._write_log()  # the log on disk follows the run, for plots of error vs steps and time
                if is_checkpoint:
                    self.save_checkpoint(self.wall_before + time.perf_counter() - t0)
                    self._write_log()
            read_back()
        finally:
            bar.close()
        wall = self.wall_before + time.perf_counter() - t0
        # a run cut by its budget ends with a held-out figure for run.json; one stopped by a signal goes on later,
        # and an evaluation here would stay in its log as a point an uninterrupted run does not have
        if status not in ("completed", "sigterm") and self.log_rows and cfg.train.eval_every > 0:
            last_psnr = self.evaluate()
            self.log_rows[-1]["eval_psnr"] = last_psnr
            self.log_rows[-1]["eval_miou"] = self.last_eval_miou
        self.save_checkpoint(wall)
        self._write_log()
        if status == "sigterm":
            return {"status": status, "step": self.step}
        summary = self.finish(wall, status, last_psnr)
        return summary

    def parameter_counts(self) -> dict[str, int]:
        groups = self.model.param_groups() if hasattr(self.model, "param_groups") else {"all": list(
            self.model.parameters())}
        counts = {k: int(sum(p.numel() for p in v)) for k, v in groups.items()}
        counts["total"] = int(sum(p.numel() for p in self.model.parameters()))
        return counts

    def finish(self, wall: float, status: str, eval_psnr: float | None) -> dict[str, Any]:
        """Write model.pt and run.json (the run is complete once run.json exists)."""
        cfg = self.config
        frame_states = [state_vector(self.ds, f).astype(float).tolist() for f in self.ds.frames]
        payload = {
            "format": MODEL_FORMAT,
            "method": cfg.method,
            "config": cfg.to_dict(),
            "info": self.info.to_dict(),
            "state_dict": self.model.state_dict(),
            "normalization": self.norm.to_dict(),
            "frame_states": frame_states,
            "frame_ids": [f.frame_id for f in self.ds.frames],
            "step": self.step,
            "language_encoder": self.language.encoder if self.language else None,
        }
        if self.cameras is not None:  # absent when off: model.pt as before the option existed
            payload["camera_opt"] = self.camera_payload()
        save_atomically(payload, self.out / "model.pt")
        if self.log_gains is not None:
            write_json(self.out / EXPOSURE_FILE, {"spread": self.appearance.get("spread"), "log_gains": self.log_gains})
        run = {
            "method": cfg.method,
            "preset": cfg.preset,
            "status": status,
            "steps": self.step,
            "train_seconds": round(wall, 2),
            "device": str(self.device) + (f" ({torch.cuda.get_device_name(self.device)})"
                                          if self.device.type == "cuda" else ""),
            "mixed_precision": str(self.amp_dtype).replace("torch.", "") if self.amp_dtype else "off",
            "torch_threads": torch.get_num_threads(),
            "machine": machine_info(str(self.device)),
            "params": self.parameter_counts(),
            "peak_memory_mib": round(peak_memory_mib(self.device), 1),
            "peak_memory_kind": "cuda max_memory_allocated" if self.device.type == "cuda" else "process max RSS",
            # CUDA graphs' replays allocate nothing: their private pools show in what the allocator reserved
            "peak_reserved_mib": round(torch.cuda.max_memory_reserved(self.device) / 2**20, 1)
            if self.device.type == "cuda" else None,
            "cuda_graphs": bool(self.step_graphs is not None and self.step_graphs.captured),  # steps were replayed
            "objects": list(self.ds.objects),
            "state_mode": cfg.model.state.mode,
            "appearance": self.appearance,
            "background": self.config.model.sampling.background_mode,
            "language": bool(self.language),
            "normalization": self.norm.to_dict(),
            "eval_psnr": eval_psnr,
            "eval_miou": self.last_eval_miou,
            "data": str(cfg.data),
            "data_digest": self.data_digest,
            "code_digest": code_digest(),
            "seed": cfg.seed,
            "rays_per_step": cfg.train.batch_rays,
        }
        if self.cameras is not None:
            run["camera_opt"] = self.camera_summary()
        if self.key_frame_ranges:  # key values in a unit of the annotator's, mapped to [0, 1]
            run["key_frame_ranges"] = self.key_frame_ranges
        if self.ds.split_note:
            run["split"] = self.ds.split_note
        if status == "completed":
            write_json(self.finished_record, run)
        write_json(self.out / "run.json", run)
        return run
