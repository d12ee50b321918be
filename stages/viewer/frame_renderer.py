"""One request -> one image through the run API (``LoadedRun.render_rays``), a chunk of rays at a time.

Rendering chunk by chunk is what lets a newer request cut a full-resolution render short: between two
chunks the render loop's ``should_stop`` is asked. Colour goes through the run's fast path
(``outputs=("rgb",)``, docs/model.md); a relevancy query renders only the output its map needs and shows
the map in the turbo colour map (blue 0 .. red 1) instead of colour.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import cv2
import numpy as np

from stages.scene import generate_rays

from .language_controls import LanguageControls
from .render_loop import RenderCancelled, RenderRequest
from .resolution import Resolution


def to_uint8(rgb: np.ndarray) -> np.ndarray:
    """Float RGB in [0, 1] -> uint8, rounded (as `livescene render` writes rgb.png)."""
    return np.clip(np.asarray(rgb, dtype=np.float32) * 255.0 + 0.5, 0, 255).astype(np.uint8)


def relevancy_colours(relevancy: np.ndarray) -> np.ndarray:
    """``[H, W]`` relevancy in [0, 1] -> uint8 RGB in the turbo colour map."""
    grey = to_uint8(np.clip(relevancy, 0.0, 1.0))
    return np.ascontiguousarray(cv2.applyColorMap(grey, cv2.COLORMAP_TURBO)[..., ::-1])


class FrameRenderer:
    """The render function of the viewer's render loops (``RenderFunction``)."""

    def __init__(self, run: Any, language: LanguageControls | None, chunk_rays: int = 2048) -> None:
        self.run = run
        self.language = language
        self.chunk_rays = max(1, int(chunk_rays))

    def outputs_for(self, request: RenderRequest) -> tuple[str, ...]:
        if request.query is None:
            return ("rgb",)
        return LanguageControls.outputs_for(request.source)

    def render_outputs(self, request: RenderRequest, size: Resolution,
                       should_stop: Callable[[], bool] = lambda: False) -> dict[str, np.ndarray]:
        """The run's outputs for ``request`` at ``size``: ``{name: [H, W, ...]}``; RenderCancelled when told."""
        camera = request.view.camera(size.width, size.height)
        origins, directions = generate_rays(camera, request.view.c2w)
        origins, directions = origins.reshape(-1, 3), directions.reshape(-1, 3)
        state = np.asarray(request.states, dtype=np.float64)
        outputs = self.outputs_for(request)
        parts: dict[str, list[np.ndarray]] = {}
        for start in range(0, origins.shape[0], self.chunk_rays):
            if should_stop():
                raise RenderCancelled
            stop = start + self.chunk_rays
            out = self.run.render_rays(origins[start:stop], directions[start:stop], state, 0.0, outputs)
            for name, value in out.items():
                parts.setdefault(name, []).append(value)
        return {name: np.concatenate(chunks).reshape(size.height, size.width, *chunks[0].shape[1:])
                for name, chunks in parts.items()}

    def __call__(self, request: RenderRequest, size: Resolution, should_stop: Callable[[], bool]) -> np.ndarray:
        rendered = self.render_outputs(request, size, should_stop)
        if request.query is None:
            return to_uint8(rendered["rgb"])
        if self.language is None:
            raise RuntimeError("a relevancy query reached a viewer without language controls")
        return relevancy_colours(self.language.relevancy(request.query, request.source, rendered))
