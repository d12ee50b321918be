"""Test doubles of the viewer tests: a deterministic text encoder and a tiny run whose states show in the image."""

from __future__ import annotations

import zlib
from pathlib import Path

import numpy as np
import torch

from stages.capture import capture_to_dataset, generate_capture, load_spec
from stages.language import ObjectVocabulary, build_targets
from stages.language.encoder import CachedEncoder
from stages.model import Trainer, load_config, load_run
from stages.model.tiny_overrides import TINY_MODEL_OVERRIDES

ROOT = Path(__file__).resolve().parents[2]
TINY_RUN = [
    *TINY_MODEL_OVERRIDES,
    "train.batch_rays=64", "train.warmup_steps=2", "train.eval_every=100", "train.eval_rays=64",
    "train.checkpoint_every=100", "train.render_chunk=1024", "train.threads=1", "train.max_steps=30",
    # every sample follows the state of its most probable object (the preset rejects weak ones: after 4 steps all)
    "model.probability.rejection_threshold=0",
]


class BagOfWordsEncoder(CachedEncoder):
    """A stand-in for a text model: the sum of one fixed random vector per word (no model to load)."""

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


def make_states_visible(run_dir: Path, seed: int = 0) -> None:
    """Scale the run's state planes by fixed random factors, so that every object's state changes the image.

    A few training steps cannot teach the planes over the state axis anything (they start at 1, docs/model.md),
    and with them at 1 a slider would change nothing the viewer tests could see. The factors are in [0.1, 2.5].
    """
    path = run_dir / "model.pt"
    payload = torch.load(path, map_location="cpu", weights_only=True)
    run = load_run(run_dir)
    gen = torch.Generator().manual_seed(seed)
    touched = 0
    with torch.no_grad():
        for module in run.model.modules():
            for i in getattr(module, "k_plane_indices", []):
                plane = module.planes[i]
                plane.mul_(torch.empty(plane.shape).uniform_(0.1, 2.5, generator=gen))
                touched += 1
    assert touched, "no K-Planes state planes found: the model stage changed, update make_states_visible"
    payload["state_dict"] = run.model.state_dict()
    torch.save(payload, path)


def make_viewer_run(work: Path) -> tuple[Path, Path]:
    """(dataset, run): the tiny capture (cabinet, drawer) at 64x48, 8 frames, LiveScene trained 30 steps with a
    language table whose targets come from the bag-of-words encoder."""
    torch.set_num_threads(1)
    spec = load_spec(ROOT / "config" / "captures" / "tiny.yaml")
    spec.video.n_frames = 8
    spec.video.width, spec.video.height = 64, 48
    spec.render.texture_size = 64
    spec.render.supersample = 1
    capture = generate_capture(spec, work / "capture", progress=False)
    ds = capture_to_dataset(capture, work / "dataset", split="alternate", progress=False)
    targets = build_targets(ObjectVocabulary.from_dataset(ds.root), BagOfWordsEncoder()).write(work / "targets.npz")
    config = load_config("cpu-demo", TINY_RUN, data=str(ds.root), seed=0, language_targets=str(targets))
    Trainer(config, work / "run", device="cpu", progress=False).train()
    make_states_visible(work / "run")
    return ds.root, work / "run"
