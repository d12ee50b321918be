"""``livescene capture``: generate a synthetic capture, render its truth, or turn its truth into a scene dataset.

    livescene capture --spec config/captures/demo.yaml --out DIR [--force]
    livescene capture render --capture DIR --pose 12 [--states cabinet=1 drawer=0.5] --out view.png
    livescene capture dataset --capture DIR --out DS [--split alternate] [--every N]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import cv2
import numpy as np

from stages.scene import InputError, atomic_path
from stages.scene.cli_errors import cli_errors

SUBCOMMANDS = ("render", "dataset")


class CaptureCliError(InputError):
    """A command-line value that cannot be used."""


def _generate_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="livescene capture",
        description="Render a synthetic interactive-room capture (video, masks, key frames, prompts) with its "
                    "ground truth in DIR/truth. Other forms: `livescene capture render --help`, "
                    "`livescene capture dataset --help`.")
    p.add_argument("--spec", required=True, help="capture spec YAML (e.g. config/captures/demo.yaml)")
    p.add_argument("--out", required=True, help="capture folder to write")
    p.add_argument("--force", action="store_true", help="replace an existing non-empty --out (only once the new "
                   "capture is complete; a failed run leaves it untouched)")
    p.add_argument("--seed", type=int, default=None, help="override the spec's seed")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    return p


def _render_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="livescene capture render",
        description="Render the truth of a capture at any pose and any object states: writes the RGB image to "
                    "--out, and next to it <stem>.depth.npy (float32 z-depth in the capture's units, 0 = no hit), "
                    "<stem>.depth.png (8-bit preview), <stem>.ids.png (uint8 object ids of mapping.yaml).")
    p.add_argument("--capture", required=True, help="capture folder written by `livescene capture`")
    p.add_argument("--pose", required=True,
                   help="an integer: the frame of truth/transforms.json with that source index; or a file: .npy "
                        "4x4, or .json holding a 4x4 list or {\"transform_matrix\": 4x4} (camera-to-world, OpenGL "
                        "axes, capture units)")
    p.add_argument("--states", nargs="*", default=[], metavar="NAME=VALUE",
                   help="object states (0 closed, 1 open); objects not named take the truth state of --pose's "
                        "frame when --pose is a frame index, else 0")
    p.add_argument("--out", required=True, help="RGB PNG to write")
    p.add_argument("--scale", type=float, default=1.0, help="image size factor relative to the capture camera")
    p.add_argument("--supersample", type=int, default=None, help="rays per pixel side (default: the spec's)")
    return p


def _dataset_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="livescene capture dataset",
        description="Write a scene dataset (stages.scene contract) straight from a capture's truth: video frames "
                    "as images, truth poses, dense truth states, one-hot masks, mapping, key frames, prompts, "
                    "scene box. Validated before it is published.")
    p.add_argument("--capture", required=True, help="capture folder written by `livescene capture`")
    p.add_argument("--out", required=True, help="scene dataset folder to write")
    p.add_argument("--split", default="alternate", choices=("alternate", "every_n", "fraction"),
                   help="train/test split of the kept frames (stages.scene.make_split)")
    p.add_argument("--split-n", type=int, default=10, help="n of the every_n split")
    p.add_argument("--every", type=int, default=1, help="keep every n-th video frame")
    p.add_argument("--images", default="video", choices=("video", "truth"),
                   help="video: decoded video.mp4 frames (what a user has); truth: lossless truth/images PNGs")
    p.add_argument("--no-masks", action="store_true",
                   help="leave out the masks, as a room filmed without them (with --no-states: no objects at all)")
    p.add_argument("--no-states", action="store_true",
                   help="leave out the frames' states and the key frames, as a room filmed without key frames")
    p.add_argument("--force", action="store_true", help="replace an existing non-empty --out")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    return p


def refuse_clobber(out: Path, force: bool) -> None:
    """Refuse to overwrite a non-empty folder (or any file) unless ``force``."""
    if out.is_file():
        raise CaptureCliError(out, "--out is an existing file", "pass a folder path")
    if out.is_dir() and any(out.iterdir()) and not force:
        raise CaptureCliError(out, "--out exists and is not empty", "pass --force to replace it, or another --out")


def parse_states(items: list[str], objects: list[str]) -> dict[str, float]:
    """``["name=value", ...]`` -> ``{name: value}``, names checked against the capture's objects."""
    out: dict[str, float] = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep:
            raise CaptureCliError(Path("--states"), f"{item!r} is not NAME=VALUE", f"write e.g. {objects[0]}=1")
        if name not in objects:
            raise CaptureCliError(Path("--states"), f"unknown object {name!r}", f"use one of {objects}")
        try:
            out[name] = float(value)
        except ValueError as exc:
            raise CaptureCliError(Path("--states"), f"{item!r}: {value!r} is not a number",
                                  "write a number, 0 closed .. 1 open") from exc
    return out


def load_pose(value: str, frames: list[dict]) -> tuple[np.ndarray, dict[str, float] | None]:
    """A camera-to-world 4x4 from a source index or a .npy/.json file; plus that frame's truth state, if any."""
    try:
        index = int(value)
    except ValueError:
        index = None
    if index is not None:
        match = [fr for fr in frames if int(fr.get("source_index", -1)) == index]
        if not match:
            raise CaptureCliError(Path("truth/transforms.json"), f"no frame with source index {index}",
                                  f"use 0..{len(frames) - 1}")
        return np.asarray(match[0]["transform_matrix"], dtype=np.float64), dict(match[0].get("state") or {})
    path = Path(value)
    if not path.is_file():
        raise CaptureCliError(path, "pose file not found", "pass a frame index or a .npy/.json 4x4 matrix")
    try:
        if path.suffix == ".npy":
            mat = np.load(path, allow_pickle=False)
        else:
            data = json.loads(path.read_text())
            mat = data["transform_matrix"] if isinstance(data, dict) else data
    except (ValueError, OSError, KeyError) as exc:
        raise CaptureCliError(path, f"cannot read a pose ({exc})",
                              "write a 4x4 list or {\"transform_matrix\": 4x4}, or save a 4x4 .npy") from exc
    mat = np.asarray(mat, dtype=np.float64)
    if mat.shape != (4, 4) or not np.isfinite(mat).all():
        raise CaptureCliError(path, f"pose has shape {mat.shape} or non-finite values", "give one finite 4x4 matrix")
    return mat, None


def _run_generate(argv: list[str]) -> int:
    from .generate import generate_capture
    from .spec import load_spec

    args = _generate_parser().parse_args(argv)
    out = Path(args.out)
    spec = load_spec(args.spec)
    if args.seed is not None:
        spec.seed = args.seed
    refuse_clobber(out, args.force)
    generate_capture(spec, out, progress=not args.no_progress, replace=args.force)
    meta = json.loads((out / "capture.json").read_text())
    effects = meta.get("camera_effects")
    cost = f" ({effects['renders_per_frame']} renders a frame: phone camera effects)" if effects else ""
    print(f"{out}: {meta['n_frames']} frames {meta['width']}x{meta['height']}, objects {meta['objects']}, "
          f"{meta['timings']['total_s']:.1f} s{cost}")
    return 0


def _run_render(argv: list[str]) -> int:
    from .renderer import TruthRenderer

    args = _render_parser().parse_args(argv)
    renderer = TruthRenderer.from_capture(args.capture)
    c2w, frame_state = load_pose(args.pose, renderer.truth_frames())
    states = dict(frame_state or {})
    states.update(parse_states(args.states, renderer.objects))
    camera = renderer.camera if args.scale == 1.0 else renderer.camera.scaled(args.scale)
    out = renderer.render(c2w, states, camera, supersample=args.supersample)
    png = Path(args.out)
    stem = png.with_suffix("")
    rgb = np.round(np.clip(out["rgb"], 0, 1) * 255).astype(np.uint8)[..., ::-1]
    depth = out["depth"]
    hit = depth > 0
    preview = np.zeros(depth.shape, dtype=np.uint8)
    if hit.any():
        lo, hi = float(depth[hit].min()), float(depth[hit].max())
        # near 255, far 1: 0 stays "nothing hit"
        preview[hit] = 1 + np.round(254 * (1 - (depth[hit] - lo) / max(hi - lo, 1e-12))).astype(np.uint8)
    for path, img in ((png, rgb), (Path(f"{stem}.depth.png"), preview), (Path(f"{stem}.ids.png"),
                                                                         out["ids"].astype(np.uint8))):
        with atomic_path(path, suffix=".png") as tmp:
            if not cv2.imwrite(str(tmp), img):
                raise CaptureCliError(path, "OpenCV could not write the PNG", "check the folder is writable")
    with atomic_path(Path(f"{stem}.depth.npy"), suffix=".npy") as tmp:
        np.save(tmp, depth)
    print(json.dumps({"rgb": str(png), "depth": f"{stem}.depth.npy", "ids": f"{stem}.ids.png",
                      "states": {n: float(states.get(n, 0.0)) for n in renderer.objects}}))
    return 0


def _run_dataset(argv: list[str]) -> int:
    from .truth_dataset import capture_to_dataset

    args = _dataset_parser().parse_args(argv)
    if args.every < 1:
        raise CaptureCliError(Path("--every"), f"{args.every} is not >= 1", "pass a positive integer")
    out = Path(args.out)
    refuse_clobber(out, args.force)
    ds = capture_to_dataset(args.capture, out, split=args.split, split_n=args.split_n, every=args.every,
                            images=args.images, progress=not args.no_progress, replace=args.force,
                            masks=not args.no_masks, states=not args.no_states)
    splits = {s: len(ds.frames_in(s)) for s in ("train", "test")}
    print(f"{out}: valid scene dataset, {len(ds.frames)} frames {splits}, objects {ds.objects}, "
          f"{len(ds.key_frames)} key frames")
    return 0


@cli_errors(sigterm=True)
def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    run = {"render": _run_render, "dataset": _run_dataset}.get(argv[0] if argv else "")
    if run is not None:
        return run(argv[1:])
    return _run_generate(argv)
