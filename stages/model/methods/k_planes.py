"""K-Planes with time (docs/method.md section 8): the "no control" reference.

The 4th coordinate is the normalised frame index ``2 t - 1`` instead of an
object state, so the field reproduces the capture as a video in time but
cannot set an object's state independently of the clock. Same six planes of
(x, y, z, t), samplers, renderer, losses and trainer as LiveScene; the time
axis has ``field.k_resolution`` cells (the K-Planes time regularisers, L1 to 1
and second-difference smoothness, act on it through the shared k-plane losses).
Rendering a frame needs its ``frame_index``: states given to ``render`` are
ignored by the field (they still condition the kept probability field, which runs at the final
sampling level only).
"""

from __future__ import annotations

import torch

from . import register_method
from .livescene import LiveSceneModel


class KPlanesTimeModel(LiveSceneModel):
    """K-Planes over (x, y, z, t)."""

    field_reads_probabilities = False  # the probability field is kept for the evaluation only

    def field_dims(self) -> tuple[int, list[tuple[int, int]] | None]:
        return 4, None

    def coordinates(self, positions: torch.Tensor, states: torch.Tensor, logits: torch.Tensor | None,
                    times: torch.Tensor) -> torch.Tensor:
        """(x, y, z, 2 t - 1)."""
        t = times.to(positions.dtype)
        return torch.cat([positions, (2.0 * t - 1.0).unsqueeze(-1)], dim=-1)


register_method("k-planes", KPlanesTimeModel)
