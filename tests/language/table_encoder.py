"""A text encoder whose vectors the test chooses: cosines, softmax weights and relevancies become hand-computable."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from stages.language import CachedEncoder


def unit(*components: float, dim: int = 8) -> np.ndarray:
    """The vector with the given leading components, zero after them (not normalised: give unit ones)."""
    v = np.zeros(dim)
    v[: len(components)] = components
    return v


class TableEncoder(CachedEncoder):
    """Each phrase maps to the vector of ``table``; any other phrase to the last axis, orthogonal to the first ones.

    The canonical negatives ("object", "things", "stuff", "texture") are unknown phrases unless the table names
    them, so by default every relevancy is against a vector orthogonal to the leading axes.
    """

    name = "table-test-encoder"

    def __init__(self, table: Mapping[str, Sequence[float]], dim: int = 8) -> None:
        self.table = {k: np.asarray(v, dtype=np.float64) for k, v in table.items()}
        self._dim = dim
        super().__init__(None)

    @property
    def dim(self) -> int:
        return self._dim

    def _encode_new(self, texts: list[str]) -> np.ndarray:
        return np.stack([self.table.get(t, unit(*[0.0] * (self._dim - 1), 1.0, dim=self._dim)) for t in texts])
