"""Phrase embeddings remembered on disk, one file per encoder.

Encoding is the slow part of a command or a grounding query on CPU; object
names, synonyms and state phrases repeat across every call, so they are kept
in ``<cache_dir>/<encoder-hash>.npz`` (arrays ``texts`` and ``vectors``, plus
``encoder`` naming the embedding space so a file is never read for another).
The file keeps the ``MAX_ENTRIES`` phrases used last: a viewer typing queries all day would otherwise grow
it, and rewrite all of it, without end.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from stages.scene import atomic_path


def default_cache_dir() -> Path:
    """``$LIVESCENE_CACHE`` or ``~/.cache/livescene``, with an ``embeddings`` subfolder."""
    import os

    base = os.environ.get("LIVESCENE_CACHE")
    return (Path(base) if base else Path.home() / ".cache" / "livescene") / "embeddings"


MAX_ENTRIES = 4096
"""Phrases kept on disk (about 6 MiB at 384 dimensions): a room's names, synonyms and state phrases are tens."""


class EmbeddingCache:
    """A text -> vector table persisted atomically as one ``.npz`` per encoder name."""

    def __init__(self, cache_dir: str | Path, encoder_name: str) -> None:
        self.encoder_name = encoder_name
        digest = hashlib.sha1(encoder_name.encode()).hexdigest()[:16]
        self.path = Path(cache_dir) / f"{digest}.npz"

    def load(self) -> dict[str, np.ndarray]:
        if not self.path.is_file():
            return {}
        try:
            with np.load(self.path, allow_pickle=False) as data:
                if str(data["encoder"]) != self.encoder_name:
                    return {}
                return {str(t): v.astype(np.float32) for t, v in zip(data["texts"], data["vectors"], strict=True)}
        except (OSError, ValueError, KeyError):
            # A damaged cache is only a lost speed-up: start afresh, it is rewritten on the next save.
            return {}

    def save(self, table: dict[str, np.ndarray]) -> None:
        """Write the last ``MAX_ENTRIES`` phrases of ``table`` (its order is the order of use, oldest first)."""
        if not table:
            return
        kept = list(table.items())[-MAX_ENTRIES:]
        texts = np.array([t for t, _ in kept], dtype=str)
        vectors = np.stack([v for _, v in kept]).astype(np.float32)
        with atomic_path(self.path, suffix=".npz") as tmp:
            np.savez(tmp, texts=texts, vectors=vectors, encoder=np.array(self.encoder_name))
