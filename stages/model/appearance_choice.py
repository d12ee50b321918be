"""``model.appearance.mode: measured`` / ``auto``: the frames' exposure, measured before the model is built.

``measured`` divides each training image by its gains as measured from its overlapping neighbours
(``stages.scene.exposure``); ``auto`` does so only where the gains vary by at least ``auto_spread``, and keeps
the images as they are otherwise (docs/model.md, "Exposure", has the measurements behind both).
"""

from __future__ import annotations

from typing import Any

from stages.scene import InputError, SceneDataset
from stages.scene.exposure import ExposureEstimate, estimate_exposure

from .config import AppearanceConfig

EXPOSURE_FILE = "exposure.json"
"""In a run folder trained with ``measured`` gains: ``{"spread", "log_gains": {frame id: [r, g, b]}}`` of every
frame the measurement tied, held-out frames included (the evaluation scores those at the nominal exposure too)."""


def resolve_appearance(config: AppearanceConfig, ds: SceneDataset,
                       measured: ExposureEstimate | None = None) -> dict[str, Any]:
    """Replace ``auto`` in ``config.mode`` by the mode the data call for; what was done and why (run.json), and
    with ``measured`` the log gains per frame id under ``log_gains`` (for the training rays, not for run.json).

    ``measured``: the dataset's estimate when it was measured once for every method (``livescene train
    --exposure``, the workflow's ``exposure`` rule), else it is measured here. The resolved mode is what the
    run's config records, so a resumed run of ``auto`` finds the same config in its checkpoint, and a reloaded
    run builds its model without measuring again."""
    if config.mode not in ("auto", "measured"):
        return {"mode": config.mode}
    estimate = measured if measured is not None else estimate_exposure(ds)
    spread = estimate.spread
    out: dict[str, Any] = {"spread": spread, "pairs": estimate.pairs, "tied_frames": int(estimate.tied.sum()),
                           "measured_by": "exposure file" if measured is not None else "trainer"}
    if config.mode == "auto":
        if spread is None:
            chosen, why = "none", "too few overlapping neighbour frames to measure the exposure"
        elif spread >= config.auto_spread:
            chosen, why = "measured", f"exposure spread {spread:.4f} >= {config.auto_spread}"
        else:
            chosen, why = "none", f"exposure spread {spread:.4f} < {config.auto_spread}"
        out.update(requested="auto", reason=why, auto_spread=config.auto_spread)
        config.mode = chosen
    if config.mode == "measured":
        if spread is None:
            raise InputError(ds.root / "transforms.json", "the frames' exposure cannot be measured: too few of them "
                             "overlap their neighbours in playback order",
                             "set model.appearance.mode=affine (learned per frame) or none, or auto")
        out["log_gains"] = {f: g.tolist() for f, g, t in zip(estimate.frame_ids, estimate.log_gains, estimate.tied,
                                                              strict=True) if t}
    return {"mode": config.mode, **out}
