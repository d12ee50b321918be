"""Opening a trained run (stages.model) from the language and evaluation stages.

Only ``stages.model.load_run`` and the run's ``config.yaml`` are used, so
these stages work with any method the model stage registers.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from stages.scene import InputError

_DATASET_KEYS = ("data", "dataset", "data_dir", "dataset_path", "dataset_dir")


def load_model_run(run_dir: str | Path, device: str = "cpu") -> Any:
    """The object of ``stages.model.load_run`` (``.objects``, ``.render(camera, c2w, states, frame_index)``)."""
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise InputError(run_dir, "run folder not found", "train one with `livescene train --data DS --out RUN`")
    from stages.model import load_run  # imported on use: the language stage's other commands need no torch

    return load_run(run_dir, device=device)


def run_dataset_root(run_dir: str | Path) -> Path | None:
    """The dataset a run was trained on, as its config.yaml records it (None when it does not say)."""
    cfg_path = Path(run_dir) / "config.yaml"
    if not cfg_path.is_file():
        return None
    try:
        cfg = yaml.safe_load(cfg_path.read_text()) or {}
    except yaml.YAMLError:
        return None
    found = _find_dataset(cfg)
    return Path(found) if found else None


def _find_dataset(cfg: Any) -> str | None:
    if not isinstance(cfg, dict):
        return None
    for key in _DATASET_KEYS:
        value = cfg.get(key)
        if isinstance(value, str) and value:
            return value
    for value in cfg.values():
        found = _find_dataset(value)
        if found:
            return found
    return None
