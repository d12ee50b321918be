"""``livescene render``: render a trained run at any pose with any object states -> rgb, depth, probabilities;
or a camera path to an mp4 video (``--camera-path``, ``--orbit``, ``--states-sweep OBJECT``; docs/export.md)."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import yaml

from stages.scene import Camera, InputError, SceneError, atomic_dir, guard_output_file, read_scene
from stages.scene.cli_errors import cli_errors
from stages.scene.state_values import parse_state_assignments
from stages.scene.transforms import parse_pose

from .camera_path import CameraPath, best_view_of, orbit_path, read_camera_path, states_sweep_path
from .path_video import (
    CODECS,
    VIDEO_SUFFIXES,
    check_frames_dir,
    check_video_codec,
    encode_video,
    frames_dir_for,
    render_frames,
)
from .run import LoadedRun, dataset_of_run, load_run


def build_parser(prog: str = "livescene render") -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=prog, description=__doc__)
    p.add_argument("--run", required=True, help="run folder written by `livescene train`")
    pose = p.add_mutually_exclusive_group(required=True)
    pose.add_argument("--pose", help="DATASET_DIR/transforms.json:FRAME_ID (or DATASET_DIR:FRAME_ID): a frame's pose")
    pose.add_argument("--pose-matrix", help="4x4 camera-to-world (OpenGL) as 16 numbers or a JSON nested list")
    pose.add_argument("--camera-path", help="nerfstudio camera_path.json (+ per-keyframe \"states\") -> video")
    pose.add_argument("--orbit", action="store_true", help="video: orbit made from the training cameras")
    pose.add_argument("--states-sweep", metavar="OBJECT",
                      help="video: OBJECT goes 0 -> 1 -> 0 seen from the training pose that shows it best")
    p.add_argument("--state", action="append", default=[], metavar="OBJECT=VALUE",
                   help="object state in [0, 1] (repeatable); objects not named keep the frame's state "
                        "(videos: objects the path does not set; default 0)")
    p.add_argument("--data", help="dataset for the camera with --pose-matrix and the training cameras of "
                   "--orbit / --states-sweep (default: the run's dataset)")
    p.add_argument("--out", required=True, help="folder for rgb.png, depth.png/.npy, prob_<object>.png, probs.npy; "
                   "with a path: the video file (.mp4); its frames go to <stem>_frames/ next to it")
    p.add_argument("--device", default="cpu", help="cpu | cuda")
    video = p.add_argument_group("videos (--camera-path, --orbit, --states-sweep)")
    video.add_argument("--fps", type=float, help="frames per second (default: the path's; made paths 12)")
    video.add_argument("--seconds", type=float, default=5.0, help="length of a made path (default 5)")
    video.add_argument("--width", type=int, help="frame width (default: the path's, or the dataset's)")
    video.add_argument("--height", type=int, help="frame height (default: the path's, or the dataset's)")
    video.add_argument("--arc", type=float, help="--orbit: degrees of arc (default: the training cameras' arc; "
                       "360 = full circle)")
    video.add_argument("--sway", type=float, default=10.0, help="--states-sweep: camera sway, +- degrees")
    video.add_argument("--codec", default="mp4v", choices=CODECS, help="OpenCV FourCC (default mp4v)")
    video.add_argument("--frames-dir", help="PNG frames folder (default <out stem>_frames next to the video)")
    video.add_argument("--threads", type=int, default=0, help="torch CPU threads (0 = torch's default)")
    video.add_argument("--no-progress", action="store_true", help="no progress bar")
    return p


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
    try:  # finite and rigid, as in a dataset; the fix spoken to the command line, not to a transforms.json
        return parse_pose(m, Path("--pose-matrix"), "the camera-to-world matrix")
    except SceneError as exc:
        raise InputError("--pose-matrix", exc.problem.replace("transform_matrix", "the matrix"),
                         "give a finite rigid camera-to-world matrix (rotation without scale, last row 0 0 0 1)") \
            from None


def _write_png(path: Path, img: np.ndarray) -> None:
    arr = np.clip(np.asarray(img, dtype=np.float64) * 255.0 + 0.5, 0, 255).astype(np.uint8)
    if arr.ndim == 3:
        arr = arr[..., ::-1]
    if not cv2.imwrite(str(path), arr):
        raise OSError(f"could not write {path}")


MIN_VIDEO_SIDE = 2
"""Smallest video side: OpenCV's writers refuse a 1-pixel frame, and only after every frame is rendered."""


def _made_path_camera(args: argparse.Namespace, camera):
    """The dataset camera at --width/--height (vertical field of view kept), without distortion."""
    w, h = args.width, args.height
    if w is None and h is None:
        w, h = camera.width, camera.height
    w = w or round(camera.width * h / camera.height)
    h = h or round(camera.height * w / camera.width)
    f = h / camera.height  # an undistorted pinhole: a video has no lens distortion to copy
    return Camera(fx=camera.fx * f, fy=camera.fy * f, cx=w / 2.0, cy=h / 2.0, width=w, height=h)


def _video_path(args: argparse.Namespace, run: LoadedRun) -> CameraPath:
    defaults = parse_state_assignments(args.state)
    unknown = sorted(set(defaults) - set(run.objects))
    if unknown:
        raise InputError("--state", f"unknown objects {unknown}", f"use {run.objects}")
    outside = {k: v for k, v in defaults.items() if not 0.0 <= v <= 1.0}
    if outside:
        raise InputError("--state", f"states {outside} are outside [0, 1]", "0 is closed, 1 fully open")
    if (args.fps is not None and not args.fps > 0) or not args.seconds > 0:
        raise InputError("--fps/--seconds", f"fps {args.fps}, seconds {args.seconds}", "give positive numbers")
    if args.camera_path:
        size = None
        if args.width or args.height:
            if not (args.width and args.height):
                raise InputError("--width/--height", "a camera path needs both", "give --width W --height H")
            size = (args.width, args.height)
        cp = read_camera_path(args.camera_path, run.objects, defaults, size)
        if args.fps:
            cp.fps = args.fps
        return cp
    ds = read_scene(dataset_of_run(args.run, args.data), validate=False)
    run.check_dataset(ds)
    train = [f for f in ds.frames if (f.split or "train") == "train"] or ds.frames
    c2ws = [np.asarray(f.c2w, dtype=np.float64) for f in train]
    camera = _made_path_camera(args, ds.camera_of(train[0]))
    fps = args.fps or 12.0
    n = max(round(fps * args.seconds), 1)
    if args.orbit:
        return orbit_path(c2ws, camera, n, fps, {o: defaults.get(o, 0.0) for o in run.objects}, args.arc)
    obj = args.states_sweep
    if obj not in run.objects:
        raise InputError("--states-sweep", f"unknown object {obj!r}", f"use one of {run.objects}")
    j = run.objects.index(obj)
    fractions = [float(ds.load_mask(f)[..., j].mean()) if ds.has_masks else 0.0 for f in train]
    base = {o: defaults.get(o, 0.0) for o in run.objects}
    return states_sweep_path(c2ws, best_view_of(fractions), camera, n, fps, obj, base, args.sway)


def _render_video(args: argparse.Namespace) -> int:
    import torch

    if args.threads > 0:
        torch.set_num_threads(args.threads)
    frames_dir = Path(args.frames_dir) if args.frames_dir else frames_dir_for(args.out)
    # before any frame is rendered: a bad --out or --frames-dir fails at once and deletes nothing
    try:
        data = dataset_of_run(args.run, args.data)
    except InputError:  # an orbit needs no dataset: only the run is guarded then
        data = None
    for name, value in (("--width", args.width), ("--height", args.height)):
        if value is not None and value < MIN_VIDEO_SIDE:
            raise InputError(name, f"{value} pixels", f"give at least {MIN_VIDEO_SIDE} (or leave it out: the path's "
                             "or the dataset's size)")
    guard_output_file(args.out, "the video", suffixes=VIDEO_SUFFIXES, inputs=[args.run, data])
    check_frames_dir(frames_dir)
    check_video_codec(args.out, args.codec)
    run = load_run(args.run, device=args.device)
    run.warn_if_states_unread(parse_state_assignments(args.state) or ([args.states_sweep] if args.states_sweep else []))
    cp = _video_path(args, run)
    model = Path(args.run) / "model.pt"
    run_id = {"run": str(Path(args.run).resolve()), "step": run.step, "model_bytes": model.stat().st_size,
              "model_mtime_ns": model.stat().st_mtime_ns}
    stats = render_frames(run, cp, frames_dir, run_id, progress=not args.no_progress)
    t = time.perf_counter()
    size = encode_video(frames_dir, len(cp.frames), cp.fps, args.out, args.codec)
    stats.update({"out": str(args.out), "frames_dir": str(frames_dir), "width": cp.width, "height": cp.height,
                  "video_fps": cp.fps, "seconds": cp.seconds, "encode_seconds": round(time.perf_counter() - t, 3),
                  "bytes": size, "source": cp.source})
    print(json.dumps(stats))
    return 0


@cli_errors(sigterm=True)
def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.camera_path or args.orbit or args.states_sweep:
        return _render_video(args)
    run = load_run(args.run, device=args.device)
    frame_index = None
    if args.pose:
        spec, _, fid = args.pose.rpartition(":")
        if not spec or not fid:
            raise InputError("--pose", f"{args.pose!r} is not PATH:FRAME_ID", "write e.g. DS/transforms.json:00012")
        root = Path(spec).parent if Path(spec).name == "transforms.json" else Path(spec)
        ds = read_scene(root)
        frame = ds.frame_by_id(fid)
        camera, c2w = ds.camera_of(frame), frame.c2w
        frame_index = run.frame_index_of(frame, ds.frames) if run.frame_ids else None
        if frame_index is None and run.state_mode == "learned":
            print(f"warning: frame {fid} is not a frame of the run's dataset, which alone has learned states: objects "
                  "not given by --state render at 0; fix: give every object's --state, or a pose of the run's "
                  "dataset", file=sys.stderr)
    else:
        c2w = _parse_matrix(args.pose_matrix)
        ds = read_scene(dataset_of_run(args.run, args.data), validate=False)
        run.check_dataset(ds)
        camera = ds.camera
    run.warn_if_states_unread(parse_state_assignments(args.state))
    out = run.render(camera, c2w, parse_state_assignments(args.state) or None, frame_index=frame_index)
    state = run.state_vector(parse_state_assignments(args.state) or None, frame_index)
    with atomic_dir(args.out, "render", inputs=[args.run], legacy=["render.yaml"]) as tmp:
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
    print(json.dumps({"out": args.out, "states": {n: float(v) for n, v in zip(run.objects, state, strict=True)}},
                     ensure_ascii=False))
    return 0
