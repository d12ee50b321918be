"""CoNeRF's learned attributes: one latent code per frame, regressed to the attribute values.

CoNeRF gives every training frame a learned latent code and regresses its
attributes from it with a small MLP; only the few annotated (key) frames
supervise the regression, the photometric loss reaches every other frame's
code through the gated attributes. Unlike LiveScene's 1D grid over frame time
(``StateField``), neighbouring frames share nothing: each code is free.
"""

from __future__ import annotations

import torch
from torch import nn

from ..mlp import mlp


class FrameLatentStates(nn.Module):
    """Normalised frame index t [N] in [0, 1] -> attributes [N, alpha] in (0, 1) via per-frame latents."""

    def __init__(self, n_frames: int, n_objects: int, latent_dim: int, hidden: int,
                 frame_times: list[float] | None = None) -> None:
        super().__init__()
        self.n_frames, self.n_objects = max(int(n_frames), 1), n_objects
        self.latents = nn.Embedding(self.n_frames, latent_dim)
        nn.init.normal_(self.latents.weight, 0.0, 0.1)
        self.decoder = mlp(latent_dim, hidden, 1, max(n_objects, 1))
        # frames timed by their numbers (SceneInfo.frame_times): a time is the nearest frame's; not saved, as the
        # run's SceneInfo holds them
        self.times: torch.Tensor | None
        times = None if frame_times is None else torch.tensor(frame_times, dtype=torch.float32)
        self.register_buffer("times", times, persistent=False)

    def frame_index(self, t: torch.Tensor) -> torch.Tensor:
        if self.times is not None:
            return (t.float()[:, None] - self.times[None, :]).abs().argmin(dim=1)
        return (t.float().clamp(0, 1) * (self.n_frames - 1)).round().long()

    def forward(self, t: torch.Tensor) -> torch.Tensor:
        return torch.sigmoid(self.decoder(self.latents(self.frame_index(t))))[:, : self.n_objects]
