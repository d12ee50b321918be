"""Throughput of the evaluation stage (`livescene evaluate`) of a LiveScene run on the demo capture (or
``--capture``'s), against the capture's truth renderer.

The capture and its truth dataset are made once into ``--work`` (child processes), and, unless ``--run`` names
one, a run is trained for ``--steps`` in a child process (cached in ``--work``; the default, 2000 steps with the
language table, is render_throughput.py's run). Then ``livescene evaluate`` runs once, then ``--repeats`` times,
in this process (its ``main``, writing into ``--work``), and the table gives, median over the repeats, the
evaluation's own timings (timings.json):

- ``held-out renders``: the run's renders of the held-out views (ms per view, rays/s);
- ``held-out scores``: the rest of the held-out part: images read, PSNR, SSIM, LPIPS (where its weights are
  on this machine), object / static regions, PNGs written;
- ``unseen: model renders``, ``unseen: truth renders + scores``: the unseen state combinations, the run's renders
  apart from the truth renderer's (open3d) and the scoring;
- ``grounding``: relevancy maps and IoU of every name and synonym query on the held-out renders (per view);
- ``locality``: the locality test, model and truth renders together (the stage times them as one; per model
  render);
- ``evaluation``: the four parts; ``livescene evaluate``: the whole call, the run's loading, the text
  encoder and the writing included; ``(first call)``: the untimed-by-the-repeats first call of the process, which
  also pays one-time imports (the first SSIM imports torchmetrics, and torchmetrics transformers), as every
  ``livescene evaluate`` process does: the parts above are the repeats after it.

Below it, the metrics alone on the held-out renders of the last repeat (PSNR, SSIM, LPIPS: ms per view).
Each row has the 1-minute load average before and after; above the table the CPU pressure before and after,
the peak RSS of this process (evaluations, not the training) and the machine (a run is in docs/language.md,
"Benchmark (evaluation)")::

    .venv/bin/python benchmarks/evaluate_throughput.py
    .venv/bin/python benchmarks/evaluate_throughput.py --run RUN --views 8
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import statistics
import time
from pathlib import Path

import this_checkout  # noqa: F401  (this checkout's stages, here and in subprocesses)
from stage_bench import (
    Row,
    add_input_arguments,
    capture_folder,
    check_repeats,
    dataset_folder,
    load_span,
    print_table,
    timed,
    trained_run,
    work_folder,
)

from stages.scene.machine import contention


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_input_arguments(p, repeats=2)
    p.add_argument("--run", type=Path, help="a trained run of the capture's dataset (default: train one)")
    p.add_argument("--steps", type=int, default=2000, help="training steps of the run made here")
    p.add_argument("--set", dest="overrides", action="append", default=[], help="training config override KEY=VALUE")
    p.add_argument("--no-language", action="store_true", help="train the run made here without the language table")
    p.add_argument("--views", type=int, default=None, help="held-out views (--max-views; default: all)")
    p.add_argument("--unseen-views", type=int, default=3, help="--unseen-views (the command's default)")
    p.add_argument("--locality-views", type=int, default=8, help="--locality-views (the command's default)")
    p.add_argument("--scale", type=float, default=1.0, help="--scale: render at this fraction of the image size")
    p.add_argument("--no-grounding", action="store_true", help="--no-grounding (no text encoder is loaded)")
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--device", default="cpu")
    args = p.parse_args()
    check_repeats(p, args)
    work = work_folder(args)
    capture, dataset = capture_folder(work, args.capture), dataset_folder(work, args.capture)
    run = args.run or trained_run(work, dataset, args.steps, args.overrides, not args.no_language)
    import cv2
    import torch

    from stages.evaluate import Lpips, cli, psnr, ssim
    from stages.scene import read_scene

    torch.set_num_threads(args.threads)
    out = work / "evaluate-bench"
    argv = ["--run", str(run), "--data", str(dataset), "--truth", str(capture), "--out", str(out), "--no-progress",
            "--unseen-views", str(args.unseen_views), "--locality-views", str(args.locality_views),
            "--scale", str(args.scale), "--device", args.device]
    argv += ["--max-views", str(args.views)] if args.views else []
    argv += ["--no-grounding"] if args.no_grounding else []
    def evaluate() -> float:
        t0 = time.perf_counter()
        with contextlib.redirect_stdout(io.StringIO()):  # the command's headline JSON
            code = cli.main(argv)
        if code:
            raise SystemExit(f"livescene evaluate {' '.join(argv)} failed with exit status {code}")
        return time.perf_counter() - t0

    before = contention()
    load0 = os.getloadavg()[0]
    # the first call pays one-time imports (the first SSIM imports torchmetrics, which imports transformers): a
    # row of its own, and the repeats after it are what a second evaluation in one process costs
    first = Row("livescene evaluate (first call)", [evaluate()], 1, "evaluation", load_span(load0))
    load0 = os.getloadavg()[0]
    walls, timings = [], []
    for _ in range(args.repeats):
        walls.append(evaluate())
        timings.append(json.loads((out / "timings.json").read_text()))
    load = load_span(load0)
    metrics = json.loads((out / "metrics.json").read_text())
    width, height = metrics["held_out"]["image_size"]

    def row(part: str, seconds: list[float], n: float, unit: str, rays: bool = False) -> Row:
        rays_per_s = {"rays/s": f"{n * width * height / statistics.median(seconds):.0f}"} if rays else None
        return Row(part, seconds, n, unit, load, rays_per_s)

    held = [t["held_out"] for t in timings]
    views = held[0]["views"]
    rows = [row("held-out renders", [h["render_seconds"] for h in held], views, "view", rays=True),
            row("held-out scores", [h["seconds"] - h["render_seconds"] for h in held], views, "view")]
    notes = []
    unseen = [t["unseen_combinations"] for t in timings]
    if unseen[0].get("model_renders"):
        renders = unseen[0]["model_renders"]
        rows += [row("unseen: model renders", [u["model_render_seconds"] for u in unseen], renders, "render", True),
                 row("unseen: truth renders + scores", [u["seconds"] - u["model_render_seconds"] for u in unseen],
                     renders, "render")]
    else:
        notes.append(f"unseen combinations: {metrics['unseen_combinations']['status']}")
    if metrics["grounding"]["status"] == "computed":
        rows.append(row("grounding", [t["grounding"]["seconds"] for t in timings], views, "view"))
    else:
        notes.append(f"grounding: {metrics['grounding']['status']}")
    if timings[0]["locality"].get("model_renders"):
        rows.append(row("locality (model + truth renders)", [t["locality"]["seconds"] for t in timings],
                        timings[0]["locality"]["model_renders"], "model render"))
    else:
        notes.append(f"locality: {metrics['locality'].get('status', 'not run')}")
    rows += [row("evaluation (the four parts)", [t["seconds"] for t in timings], 1, "evaluation"),
             row("livescene evaluate (in-process)", walls, 1, "evaluation"), first]

    # the metrics alone, on the last repeat's renders against the dataset images at the render size
    ds = read_scene(dataset)
    pairs = []
    for record in metrics["held_out"]["views"]:
        frame = next(f for f in ds.frames if f.frame_id == record["frame"])
        rendered = cv2.imread(str(out / "renders" / f"{record['frame']}.png"))[..., ::-1] / 255.0
        pairs.append((rendered, cv2.resize(ds.load_image(frame), (width, height), interpolation=cv2.INTER_AREA)))
    lpips = Lpips()
    for name, metric in (("psnr", psnr), ("ssim", ssim), ("lpips", lpips)):
        if metric is lpips and not lpips.available:
            notes.append(f"lpips: {lpips.status}")
            continue
        rows.append(timed(f"metric {name}", lambda m=metric: [m(a, b) for a, b in pairs], args.repeats, len(pairs),
                          "view"))
    print_table(f"evaluate: {run} on {dataset} ({views} held-out views at {width}x{height}, "
                f"{torch.get_num_threads()} threads, {args.device})", rows, before, args.repeats, args.device,
                extra_columns=("rays/s",), notes=tuple(notes))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
