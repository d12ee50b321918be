"""Language targets for the interaction-aware language table (docs/method.md section 7).

With a text-only encoder the target of an object at state level ``s`` is the
embedding of its state phrase ("closed fridge", "open fridge"); the model
interpolates between levels by state. The file is plain ``.npz`` so the model
stage reads it with numpy alone:

- ``objects`` [alpha] str, in state-vector order
- ``states`` [S] float32, the levels (e.g. [0, 1])
- ``embeddings`` [alpha, S, D] float32, unit rows
- ``background`` [D] float32, the embedding of the background phrase
- ``phrases`` [alpha, S] str, the phrases embedded (for people and reports)
- ``encoder`` 0-d str, the embedding space (``TextEncoder.name``)
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from stages.scene import InputError, atomic_path

from .encoder import TextEncoder
from .vocabulary import ObjectVocabulary

BACKGROUND_PHRASE = "background"


@dataclass
class LanguageTargets:
    """The arrays of a targets file, in memory."""

    objects: list[str]
    states: np.ndarray
    embeddings: np.ndarray
    background: np.ndarray
    phrases: list[list[str]]
    encoder: str

    def write(self, path: str | Path) -> Path:
        path = Path(path)
        with atomic_path(path, suffix=".npz") as tmp:
            np.savez(tmp, objects=np.array(self.objects, dtype=str), states=self.states.astype(np.float32),
                     embeddings=self.embeddings.astype(np.float32), background=self.background.astype(np.float32),
                     phrases=np.array(self.phrases, dtype=str), encoder=np.array(self.encoder))
        return path

    @classmethod
    def read(cls, path: str | Path) -> LanguageTargets:
        path = Path(path)
        try:
            with np.load(path, allow_pickle=False) as d:
                out = cls(objects=[str(o) for o in d["objects"]], states=d["states"], embeddings=d["embeddings"],
                          background=d["background"], phrases=d["phrases"].tolist(), encoder=str(d["encoder"]))
        except (OSError, ValueError, KeyError) as exc:
            raise InputError(path, f"not a language targets file ({exc})",
                             "write it with `livescene language targets --data DS --out targets.npz`") from exc
        alpha, s = len(out.objects), len(out.states)
        if out.embeddings.shape[:2] != (alpha, s) or out.background.shape != out.embeddings.shape[2:]:
            raise InputError(path, f"embeddings {out.embeddings.shape} / background {out.background.shape} do not "
                             f"match {alpha} objects x {s} states", "re-create the file")
        return out


def build_targets(vocabulary: ObjectVocabulary, encoder: TextEncoder,
                  levels: Sequence[float] = (0.0, 1.0), background_phrase: str = BACKGROUND_PHRASE) -> LanguageTargets:
    """Embed every object's state phrase at every level, plus the background phrase."""
    levels = sorted(float(v) for v in levels)
    if not levels or levels[0] < 0 or levels[-1] > 1 or len(set(levels)) != len(levels):
        raise InputError("--levels", f"state levels {levels} are not distinct values in [0, 1]",
                         "give e.g. --levels 0,1 or --levels 0,0.5,1")
    phrases = [[e.state_phrase(v) for v in levels] for e in vocabulary.entries]
    flat = [p for row in phrases for p in row]
    vectors = encoder.encode([*flat, background_phrase])
    dim = vectors.shape[1]
    emb = vectors[:-1].reshape(len(vocabulary.entries), len(levels), dim)
    return LanguageTargets(objects=vocabulary.objects, states=np.asarray(levels, dtype=np.float32),
                           embeddings=emb.astype(np.float32), background=vectors[-1].astype(np.float32),
                           phrases=phrases, encoder=encoder.name)


def build_crop_targets(dataset, encoder, levels: Sequence[float] = (0.0, 1.0), frames_per_level: int = 8,
                       background_phrase: str = BACKGROUND_PHRASE) -> LanguageTargets:
    """The paper's image targets, gathered into the table: mean masked-crop feature per object and state level.

    ``dataset`` is a ``stages.scene.SceneDataset`` with masks and per-frame
    states; ``encoder`` must have ``encode_images`` (OpenCLIP). Each training
    frame goes to the level nearest its state; up to ``frames_per_level``
    evenly spaced frames per (object, level) are encoded. A level no frame
    reaches falls back to the text embedding of its state phrase, and that is
    recorded in ``phrases`` as "text: <phrase>".
    """
    from .openclip_encoder import masked_object_crop
    from .vocabulary import ObjectVocabulary

    if not hasattr(encoder, "encode_images"):
        raise InputError("--crop-targets", f"encoder {encoder.name!r} has no image side",
                         "use --encoder openclip with local weights, or drop --crop-targets")
    vocabulary = ObjectVocabulary.from_prompts(dataset.objects, dataset.prompts, dataset.root / "prompts.yaml")
    text = build_targets(vocabulary, encoder, levels, background_phrase)
    level_arr = text.states.astype(np.float64)
    frames = [f for f in dataset.frames_in("train") if f.state]
    emb = text.embeddings.copy()
    phrases = [[f"text: {p}" for p in row] for row in text.phrases]
    for k, name in enumerate(dataset.objects):
        for j, _ in enumerate(level_arr):
            members = [f for f in frames if name in f.state
                       and int(np.argmin(np.abs(level_arr - f.state[name]))) == j]
            if not members:
                continue
            pick = [members[i] for i in np.linspace(0, len(members) - 1, min(frames_per_level, len(members))).round()
                    .astype(int)]
            crops = []
            for f in pick:
                crop = masked_object_crop(dataset.load_image(f), dataset.load_mask(f)[..., k])
                if crop is not None:
                    crops.append(crop)
            if crops:
                mean = encoder.encode_images(crops).mean(0)
                emb[k, j] = mean / max(float(np.linalg.norm(mean)), 1e-12)
                phrases[k][j] = f"crops: {len(crops)} frames"
    return LanguageTargets(objects=text.objects, states=text.states, embeddings=emb, background=text.background,
                           phrases=phrases, encoder=text.encoder)
