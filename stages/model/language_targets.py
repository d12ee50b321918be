"""Per-pixel language targets from a targets .npz (docs/data-contract.md, "Language targets"), read with numpy alone.

A pixel of object ``j`` whose state is ``kappa_j`` takes object ``j``'s
state-level embeddings interpolated linearly at ``kappa_j``; background pixels
take the background embedding.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from stages.scene import InputError


class LanguageTargets:
    """Embeddings [alpha, S, D] at state levels [S], background [D], in the dataset's object order."""

    def __init__(self, levels: np.ndarray, embeddings: np.ndarray, background: np.ndarray, encoder: str) -> None:
        self.levels = torch.tensor(np.asarray(levels, dtype=np.float32))
        self.embeddings = torch.tensor(np.asarray(embeddings, dtype=np.float32))
        self.background = torch.tensor(np.asarray(background, dtype=np.float32))
        self.encoder = encoder

    @property
    def dim(self) -> int:
        return int(self.background.shape[0])

    @classmethod
    def read(cls, path: str | Path, objects: list[str]) -> LanguageTargets:
        path = Path(path)
        fix = "write it with `livescene language targets --data DS --out targets.npz`"
        try:
            with np.load(path, allow_pickle=False) as d:
                names = [str(o) for o in d["objects"]]
                levels, emb, bg = d["states"], d["embeddings"], d["background"]
                encoder = str(d["encoder"]) if "encoder" in d else "unknown"
        except (OSError, ValueError, KeyError) as exc:
            raise InputError(path, f"not a language targets file ({exc})", fix) from exc
        missing = [o for o in objects if o not in names]
        if missing:
            raise InputError(path, f"no embeddings for objects {missing} (file has {names})",
                             "make the targets from the same dataset")
        if emb.ndim != 3 or emb.shape[:2] != (len(names), len(levels)) or bg.shape != emb.shape[2:]:
            raise InputError(path, f"embeddings {emb.shape} / background {bg.shape} do not match "
                             f"{len(names)} objects x {len(levels)} states", fix)
        if not (np.isfinite(emb).all() and np.isfinite(bg).all() and np.isfinite(levels).all()):
            raise InputError(path, "embeddings or levels are not finite", fix)
        order = np.argsort(levels)
        emb = emb[[names.index(o) for o in objects]][:, order]
        return cls(np.asarray(levels)[order], emb, bg, encoder)

    def to(self, device: torch.device | str) -> LanguageTargets:
        out = LanguageTargets.__new__(LanguageTargets)
        out.levels, out.embeddings = self.levels.to(device), self.embeddings.to(device)
        out.background, out.encoder = self.background.to(device), self.encoder
        return out

    def targets(self, labels: torch.Tensor, states: torch.Tensor) -> torch.Tensor:
        """labels [R] (0..alpha-1 object, alpha background, -1 none) and states [R, alpha] -> [R, D] unit rows."""
        n_obj, n_lvl = self.embeddings.shape[:2]
        obj = labels.clamp(0, max(n_obj - 1, 0))
        if n_obj == 0:
            return F.normalize(self.background.expand(labels.shape[0], -1), dim=-1)
        value = torch.gather(states, 1, obj[:, None])[:, 0].detach() if states.shape[1] else torch.zeros_like(
            labels, dtype=torch.float32)
        if n_lvl == 1:
            emb = self.embeddings[obj, 0]
        else:
            hi = torch.searchsorted(self.levels, value.contiguous()).clamp(1, n_lvl - 1)
            lo = hi - 1
            l0, l1 = self.levels[lo], self.levels[hi]
            frac = ((value - l0) / (l1 - l0).clamp(min=1e-8)).clamp(0, 1).unsqueeze(-1)
            emb = self.embeddings[obj, lo] * (1 - frac) + self.embeddings[obj, hi] * frac
        emb = torch.where((labels >= n_obj).unsqueeze(-1), self.background.expand_as(emb), emb)
        return F.normalize(emb, dim=-1)
