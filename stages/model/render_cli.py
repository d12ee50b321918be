"""``livescene render``: render a trained run at any pose with any object states -> rgb, depth, probabilities."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import cv2
import numpy as np
import yaml

from stages.scene import InputError, atomic_dir, read_scene

from .run import load_run


def build_parser(prog: str = "livescene render") -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=prog, description=__doc__)
    p.add_argument("--run", required=True, help="run folder written by `livescene train`")
    pose = p.add_mutually_exclusive_group(required=True)
    pose.add_argument("--pose", help="DATASET_DIR/transforms.json:FRAME_ID (or DATASET_DIR:FRAME_ID): a frame's pose")
    pose.add_argument("--pose-matrix", help="4x4 camera-to-world (OpenGL) as 16 numbers or a JSON nested list")
    p.add_argument("--state", action="append", default=[], metavar="OBJECT=VALUE",
                   help="object state in [0, 1] (repeatable); objects not named keep the frame's state")
    p.add_argument("--data", help="dataset for the camera with --pose-matrix (default: the run's dataset)")
    p.add_argument("--out", required=True, help="folder for rgb.png, depth.png/.npy, prob_<object>.png, probs.npy")
    p.add_argument("--device", default="cpu", help="cpu | cuda")
    return p


def _parse_states(items: list[str]) -> dict[str, float]:
    out = {}
    for item in items:
        if "=" not in item:
            raise InputError("--state", f"{item!r} is not OBJECT=VALUE", "write e.g. --state fridge=1")
        name, value = item.split("=", 1)
        try:
            out[name.strip()] = float(value)
        except ValueError as exc:
            raise InputError("--state", f"{item!r}: {value!r} is not a number", "write a value in [0, 1]") from exc
    return out


def _parse_matrix(text: str) -> np.ndarray:
    try:
        if text.strip().startswith("["):
            values = json.loads(text)
        else:
            values = [float(x) for x in text.replace(",", " ").split()]
        m = np.asarray(values, dtype=np.float64).reshape(4, 4)
    except (ValueError, json.JSONDecodeError) as exc:
        raise InputError("--pose-matrix", f"cannot read a 4x4 matrix from {text!r}",
                         "give 16 numbers, row major, or a JSON [[...], ...] list") from exc
    return m


def _write_png(path: Path, img: np.ndarray) -> None:
    arr = np.clip(np.asarray(img, dtype=np.float64) * 255.0 + 0.5, 0, 255).astype(np.uint8)
    if arr.ndim == 3:
        arr = arr[..., ::-1]
    cv2.imwrite(str(path), arr)


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        run = load_run(args.run, device=args.device)
        frame_index = None
        if args.pose:
            spec, _, fid = args.pose.rpartition(":")
            if not spec or not fid:
                raise InputError("--pose", f"{args.pose!r} is not PATH:FRAME_ID", "write e.g. DS/transforms.json:00012")
            root = Path(spec).parent if Path(spec).name == "transforms.json" else Path(spec)
            ds = read_scene(root)
            frame = next((f for f in ds.frames if f.frame_id == fid), None)
            if frame is None:
                raise InputError(root / "transforms.json", f"no frame with id {fid!r}",
                                 "pick a frame id of the dataset")
            camera, c2w = ds.camera_of(frame), frame.c2w
            if [f.frame_id for f in ds.frames] == run.frame_ids:
                frame_index = ds.frames.index(frame)
        else:
            c2w = _parse_matrix(args.pose_matrix)
            data = args.data or run.config.data
            camera = read_scene(data, validate=False).camera
        out = run.render(camera, c2w, _parse_states(args.state) or None, frame_index=frame_index)
        state = run.state_vector(_parse_states(args.state) or None, frame_index)
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    with atomic_dir(args.out) as tmp:
        _write_png(tmp / "rgb.png", out["rgb"])
        depth = out["depth"]
        lo, hi = float(np.percentile(depth, 1)), float(np.percentile(depth, 99))
        _write_png(tmp / "depth.png", 1.0 - np.clip((depth - lo) / max(hi - lo, 1e-9), 0, 1))
        np.save(tmp / "depth.npy", depth.astype(np.float32))
        np.save(tmp / "probs.npy", out["probs"].astype(np.float32))
        for j, name in enumerate([*run.objects, "background"]):
            _write_png(tmp / f"prob_{name}.png", out["probs"][..., j])
        (tmp / "render.yaml").write_text(yaml.safe_dump({
            "run": str(args.run), "pose": args.pose or "matrix", "frame_index": frame_index,
            "states": {n: float(v) for n, v in zip(run.objects, state, strict=True)},
            "depth_png_range": [lo, hi], "depth_units": "dataset units, distance along the ray"}, sort_keys=False))
    print(json.dumps({"out": args.out, "states": {n: float(v) for n, v in zip(run.objects, state, strict=True)}}))
    return 0
