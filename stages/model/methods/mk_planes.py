"""MK-Planes and MK-Planes* (docs/method.md section 8): K-Planes over the full (3 + alpha)-D state space.

Instead of projecting the alpha interaction variables to one per sample (the
LiveScene k-projection), every sample's coordinate is
``(x, y, z, 2 kappa_1 - 1, ..., 2 kappa_alpha - 1)`` and the field factorises
that (3 + alpha)-D space into planes:

- MK-Planes: every axis pair, ``C(3 + alpha, 2)`` planes per scale, so the
  parameter count grows quadratically with the number of objects;
- MK-Planes*: only ``xy, xz, yz`` and ``(x, k_i), (y, k_i), (z, k_i)`` for each
  object, ``3 + 3 alpha`` planes per scale (linear growth, no state-state planes).

The proposal density fields use the same pair list, so only the field differs
from LiveScene: samplers, renderer, losses and trainer are shared. The
interaction probability field is kept (trained by the same mask losses) so
every method renders ``probs`` for the evaluation; it does not feed the field, so it runs at the final
sampling level only (``field_reads_probabilities``).
"""

from __future__ import annotations

import torch

from ..config import ModelConfig
from ..encodings import all_pairs
from . import register_method
from .livescene import LiveSceneModel, SceneInfo

SPATIAL_PAIRS: list[tuple[int, int]] = [(0, 1), (0, 2), (1, 2)]


def mk_planes_pairs(n_objects: int) -> list[tuple[int, int]]:
    """All ``C(3 + alpha, 2)`` axis pairs of (x, y, z, k_1..k_alpha)."""
    return all_pairs(3 + n_objects)


def mk_planes_star_pairs(n_objects: int) -> list[tuple[int, int]]:
    """``xy, xz, yz`` plus ``(x, k_i), (y, k_i), (z, k_i)`` per object: ``3 + 3 alpha`` pairs."""
    return SPATIAL_PAIRS + [(axis, 3 + i) for i in range(n_objects) for axis in range(3)]


def state_coordinates(positions: torch.Tensor, states: torch.Tensor) -> torch.Tensor:
    """(x, y, z) in [-1, 1] and states [N, alpha] in [0, 1] -> [N, 3 + alpha] in [-1, 1]."""
    return torch.cat([positions, (2.0 * states - 1.0).to(positions.dtype)], dim=-1)


class MKPlanesModel(LiveSceneModel):
    """K-Planes over all pairs of (x, y, z, k_1..k_alpha)."""

    field_reads_probabilities = False  # the probability field is kept for the evaluation only

    def __init__(self, config: ModelConfig, info: SceneInfo) -> None:
        super().__init__(config, info)

    def plane_pairs(self) -> list[tuple[int, int]]:
        return mk_planes_pairs(self.info.n_objects)

    def field_dims(self) -> tuple[int, list[tuple[int, int]] | None]:
        return 3 + self.info.n_objects, self.plane_pairs()

    def coordinates(self, positions: torch.Tensor, states: torch.Tensor, logits: torch.Tensor | None,
                    times: torch.Tensor) -> torch.Tensor:
        """Every object's state is a coordinate (the probability field does not feed the field)."""
        return state_coordinates(positions, states)


class MKPlanesStarModel(MKPlanesModel):
    """K-Planes over xy, xz, yz and (x, k_i), (y, k_i), (z, k_i): no plane couples two objects' states."""

    def plane_pairs(self) -> list[tuple[int, int]]:
        return mk_planes_star_pairs(self.info.n_objects)


register_method("mk-planes", MKPlanesModel)
register_method("mk-planes-star", MKPlanesStarModel)
