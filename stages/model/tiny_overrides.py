"""The cpu-demo preset shrunk until a training step takes milliseconds on one core.

Tests and the stability cases train real models on tiny scenes; they share these overrides so that
"tiny" means one thing. Callers add their own ``train.*`` overrides (batch, checkpoints, threads).
"""

from __future__ import annotations

TINY_MODEL_OVERRIDES: tuple[str, ...] = (
    "model.field.base_resolution=8", "model.field.k_resolution=4", "model.field.scales=[1]",
    "model.field.channels=4", "model.field.hidden=16", "model.field.color_hidden=16",
    "model.proposal.resolutions=[[8,4]]", "model.proposal.hidden=8", "model.probability.resolution=8",
    "model.probability.hidden=8", "model.sampling.num_proposal_samples=[12]", "model.sampling.num_samples=6",
)
