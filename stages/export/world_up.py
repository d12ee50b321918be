"""Which world axis is up, for formats that fix their own (glTF: +y; docs/export.md, "Formats").

People hold cameras roughly upright, so the cameras' mean up vector (OpenGL ``c2w`` column 1) lies near the
world's up; the nearest signed axis is taken. A dataset from the poses stage is z-up by construction
(docs/poses.md, "World frame"), and this rule finds that; a dataset given with its own poses keeps its own
convention and is read the same way.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

AXES = ("x", "y", "z")


def world_up_axis(c2w: Sequence[np.ndarray]) -> str:
    """'+z', '-y', ...: the signed world axis nearest the cameras' mean up vector ('+y' without cameras)."""
    ups = np.array([np.asarray(p, float)[:3, 1] for p in c2w]).reshape(-1, 3)
    mean = ups.sum(axis=0)
    if not len(ups) or not np.isfinite(mean).all() or np.linalg.norm(mean) < 1e-9:
        return "+y"
    i = int(np.argmax(np.abs(mean)))
    return ("+" if mean[i] > 0 else "-") + AXES[i]
