"""One tiny 3-object label set, and writers for every format `livescene labels` reads."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import yaml

from stages.labels import encode_counts_string, encode_rle
from stages.scene import label_map_to_onehot

HEIGHT, WIDTH = 48, 64
NAMES = ("door", "drawer", "fridge")
IDS = (3, 5, 7)  # pixel values of the PNG id maps: deliberately not 1..n


@dataclass
class LabelSetFiles:
    frames: Path
    """FRAMES folder: images/ + frames.csv, 4 frames (the last one unlabelled)."""
    labels: dict[str, np.ndarray]
    """frame id -> uint16 map, 0 background, k = NAMES[k - 1]."""
    root: Path


def make_label_maps() -> dict[str, np.ndarray]:
    """Three frames: an L-shaped door, a triangular drawer, a round fridge; frame 2 has a 9-pixel fridge only."""
    out = {}
    for i in range(3):
        lab = np.zeros((HEIGHT, WIDTH), np.uint8)
        if i < 2:
            lab[5 + i:20, 5:10] = 1
            lab[15:20, 5:25 + i] = 1
            cv2.fillPoly(lab, [np.array([[30, 5], [55 - 3 * i, 5], [30, 30]], np.int32)], 2)
            cv2.circle(lab, (45, 38), 6 + i, 3, -1)
        else:
            lab[40:43, 10:13] = 3  # 9 pixels < 48 * 64 / 300 = 10.24: unreliable
        out[f"{2 * i:05d}"] = lab.astype(np.uint16)
    return out


def contours(mask: np.ndarray) -> list[np.ndarray]:
    found, _ = cv2.findContours(mask.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    return [c.reshape(-1, 2) for c in found]


def write_frames(root: Path, n: int = 4) -> Path:
    frames = root / "frames"
    (frames / "images").mkdir(parents=True)
    rows = ["frame,source_index,timestamp,sharpness"]
    for i in range(n):
        name = f"frame_{2 * i:05d}.png"
        cv2.imwrite(str(frames / "images" / name), np.full((HEIGHT, WIDTH, 3), 40 * i, np.uint8))
        rows.append(f"{name},{2 * i},{0.2 * i},1.0")
    (frames / "frames.csv").write_text("\n".join(rows) + "\n")
    return frames


def write_png(root: Path, labels: dict[str, np.ndarray]) -> Path:
    out = root / "png"
    (out / "masks").mkdir(parents=True)
    lut = np.array([0, *IDS], np.uint8)
    for fid, lab in labels.items():
        cv2.imwrite(str(out / "masks" / f"frame_{fid}.png"), lut[lab])
    (out / "mapping.yaml").write_text(yaml.safe_dump(dict(zip(IDS, NAMES, strict=True))))
    return out


def write_npy(root: Path, labels: dict[str, np.ndarray]) -> Path:
    out = root / "npy" / "masks"
    out.mkdir(parents=True)
    for fid, lab in labels.items():
        np.save(out / f"{fid}.npy", label_map_to_onehot(lab.astype(np.int64) - 1, len(NAMES)))
    (out.parent / "mapping.yaml").write_text(yaml.safe_dump(dict(zip(IDS, NAMES, strict=True))))
    return out.parent


def write_coco(root: Path, labels: dict[str, np.ndarray]) -> Path:
    """Door as polygons, drawer as compressed RLE, fridge as uncompressed RLE."""
    images, annotations = [], []
    for n, (fid, lab) in enumerate(labels.items()):
        images.append({"id": 100 + n, "file_name": f"rgb/frame_{fid}.png", "height": HEIGHT, "width": WIDTH})
        for k, cid in enumerate(IDS, start=1):
            region = lab == k
            if not region.any():
                continue
            if k == 1:
                seg = [c.astype(float).ravel().tolist() for c in contours(region)]
            elif k == 2:
                seg = {"counts": encode_counts_string(encode_rle(region)), "size": [HEIGHT, WIDTH]}
            else:
                seg = {"counts": encode_rle(region), "size": [HEIGHT, WIDTH]}
            annotations.append({"id": len(annotations) + 1, "image_id": 100 + n, "category_id": cid,
                                "segmentation": seg, "iscrowd": int(k != 1)})
    categories = [{"id": cid, "name": name} for cid, name in zip(IDS, NAMES, strict=True)][::-1]
    path = root / "coco" / "instances.json"
    path.parent.mkdir(parents=True)
    path.write_text(json.dumps({"images": images, "annotations": annotations, "categories": categories}))
    return path


def write_labelme(root: Path, labels: dict[str, np.ndarray]) -> Path:
    """CoNeRF layout: annotations/<item id>.json (unpadded ids here) + mapping.yml {0: name, ...}."""
    out = root / "labelme" / "annotations"
    out.mkdir(parents=True)
    for fid, lab in labels.items():
        shapes = [{"label": NAMES[k - 1], "points": c.astype(float).tolist(), "shape_type": "polygon"}
                  for k in (3, 1, 2) for c in contours(lab == k) if len(c) >= 3]
        if (lab == 3).any() and not any(s["label"] == NAMES[2] for s in shapes):  # a tiny square: draw a rectangle
            ys, xs = np.nonzero(lab == 3)
            shapes.append({"label": NAMES[2], "points": [[xs.min(), ys.min()], [xs.max(), ys.max()]],
                           "shape_type": "rectangle"})
        doc = {"version": "5.0.1", "shapes": shapes, "imagePath": f"../rgb/1x/{int(fid)}.png",
               "imageHeight": HEIGHT, "imageWidth": WIDTH}
        (out / f"{int(fid)}.json").write_text(json.dumps(doc))
    (out.parent / "mapping.yml").write_text(yaml.safe_dump(dict(enumerate(NAMES))))
    return out
