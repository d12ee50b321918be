"""Compare two exports: Chamfer distance, and which points lie inside an (oriented) box (docs/export.md).

Used to check that exporting one object at two states changes the geometry only where the object
moves: the static part of the room (points outside the object's swept box) should coincide.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree


def nearest_distances(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance from each point of ``a`` [N, 3] to its nearest point of ``b`` [M, 3] (inf when ``b`` is empty)."""
    a, b = np.asarray(a, dtype=np.float64).reshape(-1, 3), np.asarray(b, dtype=np.float64).reshape(-1, 3)
    if len(b) == 0:
        return np.full(len(a), np.inf)
    return cKDTree(b).query(a, k=1)[0]


def chamfer_distance(a: np.ndarray, b: np.ndarray) -> float:
    """Symmetric mean nearest-neighbour distance: (mean_a d(a, B) + mean_b d(b, A)) / 2."""
    if len(a) == 0 and len(b) == 0:
        return 0.0
    if len(a) == 0 or len(b) == 0:
        return float("inf")
    return 0.5 * float(nearest_distances(a, b).mean() + nearest_distances(b, a).mean())


def inside_box(points: np.ndarray, box: np.ndarray, world_to_box: np.ndarray | None = None,
               margin: float = 0.0) -> np.ndarray:
    """Bool [N]: points inside ``box`` [[min], [max]] grown by ``margin``, after mapping them by ``world_to_box``
    (a 4x4 similarity, e.g. dataset world -> capture truth world; None = same world)."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if world_to_box is not None:
        p = p @ world_to_box[:3, :3].T + world_to_box[:3, 3]
    box = np.asarray(box, dtype=np.float64).reshape(2, 3)
    return np.all((p >= box[0] - margin) & (p <= box[1] + margin), axis=1)
