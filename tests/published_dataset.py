"""A scene in the layout the LiveScene authors publish theirs (OmniSim / InterReal), built from the hand-built room:
for tests of reading and training such datasets."""

from __future__ import annotations

import json
import math
import random
from pathlib import Path

import yaml

from stages.stability.checks.tiny_scenes import hand_built_dataset

UNITS = {"object0": 90.0, "object1": 0.3}
"""A door's angle in degrees and a drawer's travel in metres."""


def published(root: Path, *, n_frames: int = 12, blender: bool = False, shuffle: bool = False,
              keys: dict[str, dict[str, float]] | None = None) -> Path:
    """The tiny hand-built room rewritten as the authors ship a scene: transforms.json without states, splits or
    source indices, key frames in units, no scene.json."""
    hand_built_dataset(root, n_frames=n_frames)
    tpath = root / "transforms.json"
    data = json.loads(tpath.read_text())
    states = {Path(f["file_path"]).stem.rsplit("_", 1)[-1]: f["state"] for f in data["frames"]}
    for f in data["frames"]:
        for key in ("state", "split", "source_index"):
            f.pop(key, None)
    for key in ("train_filenames", "val_filenames", "test_filenames"):
        data.pop(key, None)
    if blender:
        w = data.pop("w")
        data = {"camera_angle_x": 2 * math.atan(w / (2 * data["fl_x"])), "frames": data["frames"]}
        for f in data["frames"]:
            f["file_path"] = "./" + f["file_path"].rsplit(".", 1)[0]
    if shuffle:
        random.Random(0).shuffle(data["frames"])
    tpath.write_text(json.dumps(data))
    if keys is None:
        keys = {f"frame_{fid}": {o: v * UNITS[o] for o, v in st.items()} for fid, st in states.items()
                if int(fid) % 3 == 0}
    (root / "key_frame_value.yaml").write_text(yaml.safe_dump(keys))
    (root / "scene.json").unlink()
    return root
