"""A batch of rays in normalised scene coordinates, with what each ray carries (state, frame time)."""

from __future__ import annotations

from dataclasses import dataclass

import torch


@dataclass
class RayBundle:
    """Rays in the [-1, 1]^3 scene box."""

    origins: torch.Tensor
    """[R, 3] ray origins (normalised scene coordinates)."""
    directions: torch.Tensor
    """[R, 3] unit directions."""
    nears: torch.Tensor
    """[R] start distance (normalised units)."""
    fars: torch.Tensor
    """[R] end distance (normalised units)."""
    states: torch.Tensor | None = None
    """[R, alpha] interaction variables in [0, 1] (None in learned-state mode: the state field gives them)."""
    times: torch.Tensor | None = None
    """[R] normalised frame index in [0, 1] (learned states, language by frame, K-Planes time baseline)."""

    def __len__(self) -> int:
        return self.origins.shape[0]

    def slice(self, start: int, stop: int) -> RayBundle:
        def cut(t: torch.Tensor | None) -> torch.Tensor | None:
            return None if t is None else t[start:stop]

        return RayBundle(self.origins[start:stop], self.directions[start:stop], self.nears[start:stop],
                         self.fars[start:stop], cut(self.states), cut(self.times))

    def to(self, device: torch.device | str) -> RayBundle:
        def mv(t: torch.Tensor | None) -> torch.Tensor | None:
            return None if t is None else t.to(device, non_blocking=True)

        return RayBundle(self.origins.to(device), self.directions.to(device), self.nears.to(device),
                         self.fars.to(device), mv(self.states), mv(self.times))
