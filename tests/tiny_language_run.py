"""Test helpers shared by the evaluation and viewer tests: a text encoder that needs no model, and a
LiveScene run trained for a few steps with a language table on a small render of the tiny capture."""

from __future__ import annotations

import zlib
from pathlib import Path

import numpy as np
import torch

from stages.capture import capture_to_dataset, generate_capture, load_spec
from stages.language import ObjectVocabulary, build_targets
from stages.language.encoder import CachedEncoder
from stages.model import Trainer, load_config

ROOT = Path(__file__).resolve().parents[1]


class BagOfWordsEncoder(CachedEncoder):
    """A deterministic stand-in for a text model: the sum of one fixed random vector per word."""

    name = "bag-of-words-test"

    @property
    def dim(self) -> int:
        return 64

    def _encode_new(self, texts: list[str]) -> np.ndarray:
        rows = []
        for text in texts:
            v = np.zeros(64)
            for word in text.lower().split():
                v += np.random.default_rng(zlib.crc32(word.encode())).standard_normal(64)
            rows.append(v)
        return np.array(rows)


def train_tiny_language_run(work: Path, overrides: list[str]) -> tuple[Path, Path, Path]:
    """(capture, dataset, run): the tiny capture (cabinet, drawer) at 64x48, 8 frames, LiveScene trained with
    ``overrides`` and a language table whose targets come from ``BagOfWordsEncoder``."""
    torch.set_num_threads(1)
    spec = load_spec(ROOT / "config" / "captures" / "tiny.yaml")
    spec.video.n_frames = 8
    spec.video.width, spec.video.height = 64, 48
    spec.render.texture_size = 64
    spec.render.supersample = 1
    capture = generate_capture(spec, work / "capture", progress=False)
    ds = capture_to_dataset(capture, work / "dataset", split="alternate", progress=False)
    targets = build_targets(ObjectVocabulary.from_dataset(ds.root), BagOfWordsEncoder()).write(work / "targets.npz")
    config = load_config("cpu-demo", overrides, data=str(ds.root), seed=0, language_targets=str(targets))
    Trainer(config, work / "run", device="cpu", progress=False).train()
    return capture, ds.root, work / "run"
