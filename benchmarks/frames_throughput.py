"""Throughput of the frames stage (`livescene frames`) on the demo capture's video (or ``--capture``'s).

The capture is rendered once into ``--work`` (in a child process); then, ``--repeats`` times each, this process
times:

- ``decode``: every frame of video.mp4 read through the stage's ``open_source`` (OpenCV / FFmpeg, with its
  damaged-frame checks);
- ``sharpness``: ``laplacian_variance`` of every decoded frame (held in memory: the score alone);
- ``extract_frames``: the whole stage as the workflow runs it (``--count 300 --max-side 960``, by default every
  frame of the demo at full size): decode, score, repeat check, PNG writing, frames.csv, frames.json, atomic
  folder swap;
- ``extract_frames --downscale 2 4``: the same, also writing the images_2/ and images_4/ copies.

Prints one markdown row per part: median seconds, frames per call, ms per frame, frames/s and the 1-minute load
average before and after; above it the CPU pressure before and after, the peak RSS and the machine (a run is in
docs/poses.md, "Benchmark (frames)")::

    .venv/bin/python benchmarks/frames_throughput.py
    .venv/bin/python benchmarks/frames_throughput.py --capture config/captures/tiny.yaml --repeats 1  # smoke
"""

from __future__ import annotations

import argparse
import shutil

import this_checkout  # noqa: F401  (this checkout's stages, here and in subprocesses)
from stage_bench import Row, add_input_arguments, capture_folder, check_repeats, print_table, timed, work_folder

from stages.scene.machine import contention


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_input_arguments(p)
    p.add_argument("--count", type=int, default=300, help="--count of the timed extraction (the workflow's 300)")
    p.add_argument("--max-side", type=int, default=960, help="--max-side of the timed extraction (the workflow's)")
    args = p.parse_args()
    check_repeats(p, args)
    from stages.frames import FramesConfig, extract_frames, laplacian_variance, open_source

    work = work_folder(args)
    video = capture_folder(work, args.capture) / "video.mp4"
    out = work / "frames-bench"
    n = open_source(video).n_declared
    images = [f.image for f in open_source(video)]  # one untimed pass: the decoder's first open costs extra
    before = contention()
    rows: list[Row] = [
        timed("decode (open_source)", lambda: sum(1 for _ in open_source(video)), args.repeats, n, "frame"),
        timed("sharpness (laplacian_variance)", lambda: [laplacian_variance(im) for im in images], args.repeats,
              len(images), "frame"),
    ]
    summary: dict = {}
    for part, downscale in (("extract_frames", ()), ("extract_frames --downscale 2 4", (2, 4))):
        def run(downscale: tuple[int, ...] = downscale) -> None:
            cfg = FramesConfig(source=video, out_dir=out, count=args.count, max_side=args.max_side,
                               downscale=downscale, progress=False)
            summary.update(extract_frames(cfg))
        rows.append(timed(part, run, args.repeats, n, "source frame"))
    shutil.rmtree(out, ignore_errors=True)
    print_table(f"frames: {video} ({n} frames {images[0].shape[1]}x{images[0].shape[0]}, kept {summary['n_frames']} at "
                f"{summary['width']}x{summary['height']})", rows, before, args.repeats)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
