"""A language-targets file of random embeddings, for tests that train with a language table on the tiny scene."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def random_language_targets(path: Path, objects: list[str], dim: int = 16) -> Path:
    """Writes, as ``livescene language`` does, one random embedding per object at states 0 and 1 and a background."""
    gen = np.random.default_rng(0)
    np.savez(path, objects=np.array(objects), states=np.array([0.0, 1.0]),
             embeddings=gen.normal(size=(len(objects), 2, dim)).astype(np.float32),
             background=gen.normal(size=dim).astype(np.float32), encoder=np.array("test"))
    return path
