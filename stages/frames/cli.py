"""``livescene frames``: frames of a video (or image folder) with source index, timestamp and sharpness."""

from __future__ import annotations

import argparse
from pathlib import Path

from stages.scene import InputError
from stages.scene.cli_errors import cli_errors

from .config import FramesConfig


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="livescene frames",
        description="Extract frames from an OpenCV-readable video or an image folder into OUT/images/"
                    "frame_<source index>.png, keeping the sharpest frame (variance of the Laplacian) of each "
                    "window; writes frames.csv (frame, source_index, timestamp, sharpness) and frames.json. "
                    "Damaged frames (truncated or corrupt image files, video frames FFmpeg reports damaged) are "
                    "dropped with a warning naming each and listed in frames_dropped.csv.")
    p.add_argument("--video", type=Path, required=True, help="video file, or a folder of frames in playback order")
    p.add_argument("--out", type=Path, required=True, help="output folder (replaced atomically)")
    pick = p.add_mutually_exclusive_group()
    pick.add_argument("--count", type=int, help="keep this many frames (one per equal window of the source)")
    pick.add_argument("--stride", type=int, help="keep one frame per window of this many source frames "
                                                 "(default: every frame)")
    p.add_argument("--downscale", type=int, nargs="+", default=[], metavar="F",
                   help="also write images_F/ copies downscaled by each factor (e.g. --downscale 2 4)")
    p.add_argument("--max-side", type=int, default=None, metavar="PX",
                   help="write the frames downscaled by the smallest integer factor that brings their longer side to "
                        "at most PX (masks and COLMAP models of the full size still fit; default: full size)")
    p.add_argument("--prefer-masked", type=Path, default=None, metavar="MASKS",
                   help="a frame that the mask annotations MASKS name (a folder of masks such as frame_00012.png or "
                        "IMG_12.png, one folder per object, LabelMe files, or a COCO file) is kept in its window "
                        "instead of a sharper one, so --count/--stride keep annotated frames")
    p.add_argument("--fps", type=float, help="frame rate of an image folder, for timestamps (videos carry their own)")
    p.add_argument("--accept-truncated", action="store_true",
                   help="keep the frames that decode when a video ends before its declared length")
    p.add_argument("--max-dropped", type=float, default=0.5, metavar="FRACTION",
                   help="largest share of the source's frames that may be dropped as damaged before the stage "
                        "refuses the source (default 0.5; 0 = refuse any damaged frame)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    return p


@cli_errors(sigterm=True)
def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.count is not None and args.count < 1:
        raise InputError(Path("--count"), f"{args.count} frames requested", "give --count >= 1")
    if args.stride is not None and args.stride < 1:
        raise InputError(Path("--stride"), f"stride {args.stride}", "give --stride >= 1")
    if any(f < 2 for f in args.downscale):
        raise InputError(Path("--downscale"), f"factors {args.downscale}", "give integer factors >= 2, e.g. 2 4")
    if not 0 <= args.max_dropped <= 1:
        raise InputError(Path("--max-dropped"), f"{args.max_dropped} is not a share between 0 and 1",
                         "give --max-dropped between 0 (refuse any damaged frame) and 1")
    if args.max_side is not None and args.max_side < 16:
        raise InputError(Path("--max-side"), f"{args.max_side} pixels", "give --max-side of at least 16, e.g. 960")
    if args.prefer_masked is not None and not args.prefer_masked.exists():
        raise InputError(args.prefer_masked, "mask annotations not found",
                         "pass the folder of the mask annotations, or a COCO file")
    if args.fps is not None and not args.fps > 0:
        raise InputError(Path("--fps"), f"{args.fps} frames per second", "give a positive frame rate")
    from .extraction import extract_frames
    from .selection import indices_named_in

    prefer = indices_named_in(args.prefer_masked) if args.prefer_masked is not None else frozenset()
    cfg = FramesConfig(source=args.video, out_dir=args.out, count=args.count, stride=args.stride,
                       downscale=tuple(sorted(set(args.downscale))), max_side=args.max_side, prefer=prefer,
                       fps=args.fps,
                       accept_truncated=args.accept_truncated, max_dropped=args.max_dropped,
                       progress=not args.no_progress)
    s = extract_frames(cfg)
    dropped = f", dropped {s['dropped_frame_count']} damaged (frames_dropped.csv)" if s["dropped_frame_count"] else ""
    factor = s["downscale_factor"]
    shrunk = f" (1/{factor} of {s['source_width']}x{s['source_height']})" if factor > 1 else ""
    turned = f", turned {s['rotation']} degrees as the video's header says" if s.get("rotation") else ""
    print(f"kept {s['n_frames']} of {s['decoded_frame_count']} frames ({s['selection']['rule']}){dropped}, "
          f"{s['width']}x{s['height']}{shrunk}{turned}, {s['timings']['total']:.1f} s -> {args.out}")
    return 0
