"""The frames stage end to end: source -> sharpest frame per window -> FRAMES folder."""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pandas as pd
from tqdm import tqdm

from stages.scene import atomic_dir, write_json

from .config import FramesConfig
from .errors import FrameSourceError
from .frame_source import REENCODE_FIX, SourceFrame, open_source
from .selection import WindowRule
from .sharpness import laplacian_variance

STAGE_VERSION = "1"


def frame_name(source_index: int) -> str:
    """File name of an extracted frame: the contract's ``frame_{source index:05d}.png``."""
    return f"frame_{source_index:05d}.png"


def _write_png(path: Path, image: np.ndarray) -> None:
    if not cv2.imwrite(str(path), image):
        raise OSError(f"could not write {path}")


def extract_frames(cfg: FramesConfig) -> dict[str, Any]:
    """Write ``cfg.out_dir`` atomically and return the content of frames.json.

    One streaming pass: every source frame is decoded once and scored; the
    best frame of the current window is held in memory until the window
    closes, so memory stays at two frames whatever the video length.
    """
    t_start = time.perf_counter()
    source = open_source(cfg.source, cfg.fps)
    rule = WindowRule.from_options(source.n_declared, cfg.count, cfg.stride)
    rows: list[dict[str, Any]] = []
    all_sharpness: list[float] = []
    size: tuple[int, int] | None = None

    with atomic_dir(cfg.out_dir) as out:
        image_dirs = {1: out / "images", **{f: out / f"images_{f}" for f in cfg.downscale}}
        for d in image_dirs.values():
            d.mkdir()

        def keep(frame: SourceFrame, score: float) -> None:
            name = frame_name(frame.source_index)
            _write_png(image_dirs[1] / name, frame.image)
            h, w = frame.image.shape[:2]
            for factor in cfg.downscale:
                small = cv2.resize(frame.image, (max(1, round(w / factor)), max(1, round(h / factor))),
                                   interpolation=cv2.INTER_AREA)
                _write_png(image_dirs[factor] / name, small)
            rows.append({"frame": name, "source_index": frame.source_index, "timestamp": frame.timestamp,
                         "sharpness": score})

        best: tuple[int, float, SourceFrame] | None = None  # (window, score, frame)
        n_read = 0
        with tqdm(total=source.n_declared, desc="frames", unit="frame", disable=not cfg.progress) as bar:
            for frame in source:
                if frame.position >= rule.n_total:  # more frames than the container declared
                    break
                score = laplacian_variance(frame.image)
                all_sharpness.append(score)
                size = (frame.image.shape[1], frame.image.shape[0])
                window = rule.window(frame.position)
                if best is not None and window != best[0]:
                    keep(best[2], best[1])
                    best = None
                if best is None or score > best[1]:
                    best = (window, score, frame)
                n_read += 1
                bar.update()
        if best is not None:
            keep(best[2], best[1])
        if n_read == 0:
            raise FrameSourceError(source.path, "no frame could be decoded", REENCODE_FIX)
        if n_read < rule.n_total and not cfg.accept_truncated:
            raise FrameSourceError(
                source.path,
                f"decoding stopped after {n_read} of the {rule.n_total} frames the video declares "
                f"(truncated or corrupt from frame {n_read} on)",
                REENCODE_FIX + f", or pass --accept-truncated to keep what the first {n_read} frames give")

        table = pd.DataFrame(rows, columns=["frame", "source_index", "timestamp", "sharpness"])
        table.to_csv(out / "frames.csv", index=False)
        summary = {
            "stage": "frames",
            "stage_version": STAGE_VERSION,
            "source": str(Path(cfg.source).resolve()),
            "source_kind": source.kind,
            "fps": None if math.isnan(source.fps) else source.fps,
            "source_frame_count": rule.n_total,
            "decoded_frame_count": n_read,
            "truncated": n_read < rule.n_total,
            "width": size[0] if size else None,
            "height": size[1] if size else None,
            "n_frames": len(rows),
            "selection": {"count": cfg.count, "stride": cfg.stride, "rule": rule.describe(),
                          "score": "variance of the Laplacian of the grey image"},
            "downscale": {f"images_{f}": f for f in cfg.downscale},
            "sharpness_all": [round(s, 4) for s in all_sharpness],
            "timings": {"total": time.perf_counter() - t_start},
        }
        write_json(out / "frames.json", summary)
    return summary
