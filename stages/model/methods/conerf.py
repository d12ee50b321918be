"""CoNeRF-style baseline (docs/method.md section 8), re-implemented in torch on the shared harness.

Per sample: the attribute-mask head (the shared interaction probability field:
tri-plane + MLP -> alpha + 1 logits, background last) gives soft mask
probabilities ``m``; the field sees ``m_i (2 kappa_i - 1)`` for every object
i, so a point with background mass sees no attribute (CoNeRF's masking, with
gradients from the photometric loss into the mask as in the original). Masks
are supervised with the shared focal loss on rendered logits; in
learned-state mode a per-frame latent code is regressed to the attributes and
only key frames supervise it (``FrameLatentStates``).

Encoding: the radiance field is ``ConerfField``, a multi-scale K-Planes
tri-plane over space (no attribute planes) plus a sinusoidal encoding of the
gated attributes into an MLP, chosen so it trains in the CPU budget of the
other methods. Proposal density fields are small MK-Planes* grids over
(x, y, z, gated attributes) so sample placement follows the objects' motion.
Not reproduced: HyperNeRF's deformation field and hyper-space ambient
coordinates (the gated attributes play the ambient coordinates' role).
"""

from __future__ import annotations

import torch

from ..config import ModelConfig
from ..fields.conerf_field import ConerfField
from ..fields.conerf_latent_states import FrameLatentStates
from ..language_targets import LanguageTargets
from ..ray_dataset import RayBatch
from . import register_method
from .livescene import LiveSceneModel, SceneInfo
from .mk_planes import mk_planes_star_pairs

FIELD_STATE_TERMS = ("l1_k_planes", "k_smoothness")
"""Regularisers of state planes that the CoNeRF field does not have (its attributes enter the MLP)."""


class ConerfModel(LiveSceneModel):
    """Coordinate network on (x, y, z, mask-gated attributes)."""

    def __init__(self, config: ModelConfig, info: SceneInfo) -> None:
        super().__init__(config, info)
        self.field = ConerfField(config.field, config.conerf, info.n_objects)
        if self.state_field is not None:
            self.state_field = FrameLatentStates(info.n_frames, info.n_objects, config.conerf.latent_dim,
                                                 config.state.hidden, info.frame_times)

    def field_dims(self) -> tuple[int, list[tuple[int, int]] | None]:
        # the proposal fields are built from this; the main field is replaced by ConerfField
        return 3 + self.info.n_objects, mk_planes_star_pairs(self.info.n_objects)

    def gated_attributes(self, logits: torch.Tensor, states: torch.Tensor) -> torch.Tensor:
        """[N, alpha] in [-1, 1]: each attribute times the point's mask probability for its object."""
        masks = torch.softmax(logits.float(), dim=-1)[:, : self.info.n_objects]
        return masks * (2.0 * states.float() - 1.0)

    def coordinates(self, positions: torch.Tensor, states: torch.Tensor, logits: torch.Tensor,
                    times: torch.Tensor) -> torch.Tensor:
        gated = self.gated_attributes(logits, states).to(positions.dtype)
        return torch.cat([positions, gated], dim=-1)

    def loss_dict(self, out: dict, batch: RayBatch, step: int,
                  language: LanguageTargets | None = None) -> dict[str, torch.Tensor]:
        terms = super().loss_dict(out, batch, step, language)
        for name in FIELD_STATE_TERMS:  # identically zero for this field: leave them out of the log
            terms.pop(name, None)
        return terms


register_method("conerf", ConerfModel)
