"""What a run trains on, recorded so that a checkpoint only resumes onto the same inputs.

A checkpoint carries the run's config and a digest of the training data as the
trainer sees it (the rays' pixels, labels, states, times, normalised poses and
directions, the language targets). ``--resume`` continues a checkpoint only when
both match; otherwise the run folder holds a different run (the poses were
re-estimated, a mask changed, a hyperparameter moved) and continuing it would
silently hand back a model of the old inputs (docs/model.md, "Resuming only the same run"). It also carries a
digest of the code that trains (``code_digest``): a checkpoint of other code is another run as well, and a
finished one must not stand in for a training that ``snakemake --forcerun train`` asks for after a code change.
"""

from __future__ import annotations

import functools
import hashlib
from pathlib import Path
from typing import Any

import numpy as np
import torch

EXECUTION_ONLY: dict[str, frozenset[str] | None] = {
    # None: the whole section; a set: those keys of it
    "train": frozenset({"eval_rays", "checkpoint_every", "keep_checkpoints", "log_every", "max_nonfinite",
                        "render_chunk", "compile", "compile_mode", "cuda_graphs"}),
    "trust": None,
    "data": None,
    "language_targets": None,
    "exposure": None,
    "preset": None,
}
"""Config entries a resumed run may change: how it runs, where the inputs live (their contents are in the data
digest), and the report's floors. Everything else defines what is learned, ``max_steps`` and ``max_seconds`` too
(the learning rate decays over them) and ``threads`` (the order of torch's float sums); ``eval_every`` defines the
run's log (train_log.csv's points, the report's error curves), so a change trains again rather than posing the old
log as the new setting's."""


def _learned_part(config: dict[str, Any]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in config.items():
        if key in EXECUTION_ONLY and EXECUTION_ONLY[key] is None:
            continue
        skip = EXECUTION_ONLY.get(key)
        out[key] = {k: v for k, v in value.items() if k not in skip} if skip and isinstance(value, dict) else value
    return out


def flatten_config(d: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested config sections -> ``{"train.max_steps": 1500, ...}``."""
    flat: dict[str, Any] = {}
    for key, value in d.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            flat.update(flatten_config(value, name + "."))
        else:
            flat[name] = value
    return flat


def config_differences(old: dict[str, Any], new: dict[str, Any]) -> list[str]:
    """The config keys (dotted) whose learned-run values differ between two ``RunConfig.to_dict()``s."""
    a, b = flatten_config(_learned_part(old)), flatten_config(_learned_part(new))
    return sorted(k for k in a.keys() | b.keys() if a.get(k, "<absent>") != b.get(k, "<absent>"))


def data_digest(tensors: dict[str, torch.Tensor | np.ndarray | None]) -> str:
    """SHA-256 over named tensors (name, dtype, shape and bytes, in name order); None entries count as absent."""
    h = hashlib.sha256()
    for name in sorted(tensors):
        t = tensors[name]
        if t is None:
            h.update(f"{name}:none;".encode())
            continue
        arr = t.detach().cpu().contiguous().numpy() if isinstance(t, torch.Tensor) else np.ascontiguousarray(t)
        h.update(f"{name}:{arr.dtype.str}:{arr.shape};".encode())
        h.update(arr.tobytes())
    return h.hexdigest()


TRAINING_CODE = ("model", "scene")
"""The packages under ``stages`` whose code decides what a training learns: the model and the dataset reader."""


@functools.cache
def code_digest(stages: Path | None = None) -> str:
    """SHA-256 over torch's version and every .py file of ``TRAINING_CODE`` (path and bytes, in path order) under
    ``stages`` (default: this package's own ``stages`` folder)."""
    stages = Path(__file__).resolve().parents[1] if stages is None else stages
    h = hashlib.sha256(f"torch {torch.__version__};".encode())
    for package in TRAINING_CODE:
        for path in sorted((stages / package).rglob("*.py")):
            h.update(f"{path.relative_to(stages).as_posix()};".encode())
            h.update(path.read_bytes())
    return h.hexdigest()
