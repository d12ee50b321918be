"""Write a picture of one demo capture frame with every object closed, then open (docs/images/).

    .venv/bin/python docs/scripts/capture_open_closed.py [--spec config/captures/demo.yaml]
        [--frame 40] [--out docs/images/capture_demo_open_closed.png]

Renders with the capture's own renderer (no capture folder needed): the camera pose of
video frame ``--frame``, all states 0 on the left, all 1 on the right, the object-id
masks underneath.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np

from stages.capture import SceneRenderer, load_spec
from stages.capture.camera_path import camera_path
from stages.scene import atomic_path

ROOT = Path(__file__).resolve().parents[2]


def _label(img: np.ndarray, text: str) -> np.ndarray:
    out = img.copy()
    (w, h), _ = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, 0.45, 1)
    out[: h + 10, : w + 10] = (out[: h + 10, : w + 10] * 0.3).astype(np.uint8)
    cv2.putText(out, text, (5, h + 5), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 255), 1, cv2.LINE_AA)
    return out


def open_closed_picture(spec_path: Path, out: Path, frame: int = 40, supersample: int = 2) -> Path:
    """Render frame ``frame``'s pose closed and open, with id masks; write a BGR PNG to ``out``."""
    spec = load_spec(spec_path)
    renderer = SceneRenderer(spec)
    pose = camera_path(spec)[min(frame, spec.video.n_frames - 1)]
    pose[:3, 3] *= spec.units.per_metre
    n = len(spec.objects)
    tiles, masks = [], []
    for value, word in ((0.0, "closed"), (1.0, "open")):
        res = renderer.render(pose, np.full(n, value), supersample=supersample)
        rgb = np.round(np.clip(res["rgb"], 0, 1) * 255).astype(np.uint8)[..., ::-1]
        tiles.append(_label(rgb, f"{spec.name} frame {frame}: {word}"))
        ids = res["ids"].astype(np.uint8)
        colour = cv2.applyColorMap((ids * (255 // max(n, 1))).astype(np.uint8), cv2.COLORMAP_TURBO)
        colour[ids == 0] = 40
        masks.append(_label(colour, "object ids"))
    picture = np.concatenate([np.concatenate(tiles, axis=1), np.concatenate(masks, axis=1)], axis=0)
    with atomic_path(out, suffix=".png") as tmp:
        cv2.imwrite(str(tmp), picture, [cv2.IMWRITE_PNG_COMPRESSION, 9])
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--spec", type=Path, default=ROOT / "config" / "captures" / "demo.yaml")
    p.add_argument("--frame", type=int, default=40)
    p.add_argument("--out", type=Path, default=ROOT / "docs" / "images" / "capture_demo_open_closed.png")
    args = p.parse_args()
    out = open_closed_picture(args.spec, args.out, args.frame)
    print(f"{out}: {out.stat().st_size / 1024:.0f} KB")


if __name__ == "__main__":
    main()
