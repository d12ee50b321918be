"""A run whose renders are a capture's truth: the ``LoadedRun.render`` API backed by the capture's ray caster.

It returns rgb, depth as the distance along the ray, accumulation 1 where a surface is hit and
probabilities one-hot from the object ids: what a perfectly trained LiveScene run would render.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping

import numpy as np

from stages.capture import SceneRenderer
from stages.scene import Camera
from stages.scene.camera import pixel_directions


class TruthRun:
    """The render API of ``stages.model.LoadedRun`` backed by a capture's truth renderer."""

    def __init__(self, renderer: SceneRenderer, with_probs: bool = True) -> None:
        self.renderer = renderer
        self.with_probs = with_probs
        self.calls: list[dict[str, float]] = []

    @property
    def objects(self) -> list[str]:
        return list(self.renderer.objects)

    def render(self, camera: Camera, c2w: np.ndarray, states: Mapping[str, float] | None = None,
               frame_index: int | None = None, outputs: Collection[str] = ("rgb", "depth", "accumulation", "probs"),
               ) -> dict[str, np.ndarray]:
        self.calls.append(dict(states or {}))
        out = self.renderer.render(c2w, dict(states or {}), camera, shadows=False)
        v, u = np.meshgrid(np.arange(camera.height), np.arange(camera.width), indexing="ij")
        stretch = np.linalg.norm(pixel_directions(camera, u, v), axis=-1)  # z-depth -> distance along the ray
        hit = out["depth"] > 0
        res = {"rgb": out["rgb"], "depth": (out["depth"] * stretch).astype(np.float32),
               "accumulation": hit.astype(np.float32)}
        if self.with_probs:
            ids = out["ids"]
            n = len(self.objects)
            channel = np.where((ids >= 1) & (ids <= n), ids - 1, n)  # mapping ids 1..n, background last
            res["probs"] = np.eye(n + 1, dtype=np.float32)[channel]
        return {k: v for k, v in res.items() if k in outputs}
