"""LERF-style relevancy and the softmax over objects used by commands and grounding.

LERF scores an embedding ``e`` against a query ``q`` by pairwise softmaxes
against canonical negatives: ``min_i exp(t e.q) / (exp(t e.q) + exp(t e.n_i))``
= ``min_i sigmoid(t (e.q - e.n_i))``. 0.5 means "as much like the query as
like the closest negative". LiveScene's reference uses the negatives
"object", "things", "stuff", "texture" and temperature 10 (docs/method.md section 7).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

CANONICAL_NEGATIVES: tuple[str, ...] = ("object", "things", "stuff", "texture")
TEMPERATURE = 10.0


def lerf_relevancy(embeddings: np.ndarray, query: np.ndarray, negatives: np.ndarray,
                   temperature: float = TEMPERATURE) -> np.ndarray:
    """Relevancy in [0, 1] of each ``[..., D]`` embedding to a ``[D]`` query against ``[K, D]`` negatives."""
    emb = np.asarray(embeddings, dtype=np.float64)
    s_query = emb @ np.asarray(query, dtype=np.float64)  # [...]
    s_neg = emb @ np.asarray(negatives, dtype=np.float64).T  # [..., K]
    # sigmoid written with the sign split so that large gaps neither overflow nor give NaN
    z = temperature * (s_query[..., None] - s_neg)
    pair = np.where(z >= 0, 1.0 / (1.0 + np.exp(-np.abs(z))), np.exp(-np.abs(z)) / (1.0 + np.exp(-np.abs(z))))
    return pair.min(axis=-1)


def softmax(x: np.ndarray, temperature: float = TEMPERATURE, axis: int = -1) -> np.ndarray:
    """Softmax of ``temperature * x`` along ``axis`` (numerically stable)."""
    z = temperature * np.asarray(x, dtype=np.float64)
    z = z - z.max(axis=axis, keepdims=True)
    e = np.exp(z)
    return e / e.sum(axis=axis, keepdims=True)


def object_similarities(query: np.ndarray, phrase_vectors: Sequence[np.ndarray]) -> np.ndarray:
    """Best cosine similarity of a unit query to each object's unit phrase vectors ``[n_i, D]`` -> ``[objects]``."""
    return np.array([float(np.max(v @ query)) if len(v) else -1.0 for v in phrase_vectors])
