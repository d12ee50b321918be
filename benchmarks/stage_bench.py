"""What the stage benchmarks share (frames, poses, states, language targets, evaluation): their inputs, made by
``livescene capture`` in a child process, and one table format.

Each script times calls of the stage's own functions in its process, ``--repeats`` times, and prints the median;
its peak memory is that process's max RSS, so the inputs are rendered in a child: the open3d renderer's memory
would otherwise be the peak of a benchmark that only reads a video.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from demo_dataset import DEMO_SPEC, ROOT
from train_throughput import language_targets

from stages.scene.machine import contention, machine_info, machine_line

COLUMNS = ["part", "median s", "n", "unit", "ms per unit", "units/s", "load"]
"""The columns of every stage benchmark's table (the evaluation adds rays/s)."""


def add_input_arguments(p: argparse.ArgumentParser, repeats: int = 3) -> None:
    p.add_argument("--capture", type=Path, default=DEMO_SPEC,
                   help="capture spec the inputs are generated from (default: the demo's; config/captures/tiny.yaml "
                        "for a smoke run)")
    p.add_argument("--work", type=Path, default=None,
                   help="where the capture and what is made from it are cached (default: a temp folder named after "
                        "the spec, shared with train_throughput.py)")
    p.add_argument("--repeats", type=int, default=repeats, help="timed calls of each part (the median is printed)")


def check_repeats(p: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    if args.repeats < 1:
        p.error(f"--repeats must be at least 1, got {args.repeats}")


def work_folder(args: argparse.Namespace) -> Path:
    if args.work is None:
        args.work = Path(tempfile.gettempdir()) / f"livescene-bench-{args.capture.stem}"
    args.work.mkdir(parents=True, exist_ok=True)
    return args.work


def _livescene(*argv: str) -> None:
    subprocess.run([sys.executable, "-m", *argv, "--no-progress"], check=True, cwd=ROOT, stdout=subprocess.DEVNULL)


def capture_folder(work: Path, spec: Path) -> Path:
    """``work/capture`` (what cached_demo_dataset makes), rendered by ``livescene capture`` in a child process."""
    capture = work / "capture"
    if not (capture / "truth" / "transforms.json").is_file():
        _livescene("stages.capture", "--spec", str(spec), "--out", str(capture), "--force")
    return capture


def dataset_folder(work: Path, spec: Path) -> Path:
    """``work/dataset``: the capture's truth dataset, alternate split, as cached_demo_dataset makes it."""
    capture = capture_folder(work, spec)
    dataset = work / "dataset"
    if not (dataset / "transforms.json").is_file():
        _livescene("stages.capture", "dataset", "--capture", str(capture), "--out", str(dataset), "--force")
    return dataset


def frames_folder(work: Path, spec: Path) -> Path:
    """``work/frames``: ``livescene frames`` on the capture's video with the workflow's defaults (--count 300
    --max-side 960: every frame of the demo and tiny captures, at full size)."""
    capture = capture_folder(work, spec)
    frames = work / "frames"
    if not (frames / "frames.csv").is_file():
        _livescene("stages.frames", "--video", str(capture / "video.mp4"), "--out", str(frames), "--count", "300",
                   "--max-side", "960")
    return frames


def trained_run(work: Path, dataset: Path, steps: int, overrides: tuple[str, ...] | list[str] = (),
                language: bool = True) -> Path:
    """A LiveScene run (cpu-demo) on ``dataset``, trained once into ``work`` in a child process; the plain run
    (with the language table, no overrides) is ``run-livescene-<steps>``, which the render and evaluation
    benchmarks share."""
    name = f"run-livescene-{steps}"
    if overrides or not language:
        name += "-" + hashlib.sha1(json.dumps([list(overrides), language]).encode()).hexdigest()[:8]
    run = work / name
    if not (run / "model.pt").is_file():
        cmd = [sys.executable, "-m", "stages.model", "train", "--data", str(dataset), "--method", "livescene",
               "--preset", "cpu-demo", "--out", str(run), "--max-steps", str(steps), "--max-seconds", "0",
               "--no-progress", "--resume"]
        cmd += ["--language-targets", str(language_targets(work, dataset))] if language else []
        for o in overrides:
            cmd += ["--set", o]
        subprocess.run(cmd, check=True, cwd=ROOT, stdout=subprocess.DEVNULL)
    return run


@dataclass
class Row:
    """One timed part: wall seconds of each repeat, and the units of work one call does."""

    part: str
    seconds: list[float]
    n: float
    unit: str
    load: str
    extra: dict[str, str] | None = None

    @property
    def median(self) -> float:
        return statistics.median(self.seconds)


def timed(part: str, call: Callable[..., object], repeats: int, n: float, unit: str,
          setup: Callable[[], object] | None = None) -> Row:
    """``call()`` timed ``repeats`` times, with the 1-minute load average before and after; with ``setup``,
    ``call(setup())``, the setup untimed."""
    load0 = os.getloadavg()[0]
    seconds = []
    for _ in range(repeats):
        args = () if setup is None else (setup(),)
        t0 = time.perf_counter()
        call(*args)
        seconds.append(time.perf_counter() - t0)
    return Row(part, seconds, n, unit, load_span(load0))


def load_span(load0: float) -> str:
    return f"{load0:.2f}-{os.getloadavg()[0]:.2f}"


def peak_rss_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _cell(x: float) -> str:
    if not math.isfinite(x):
        return "-"
    return f"{x:.0f}" if abs(x) >= 100 else f"{x:.3g}"


def print_table(title: str, rows: list[Row], before: str, repeats: int, device: str | None = None,
                extra_columns: tuple[str, ...] = (), notes: tuple[str, ...] = ()) -> None:
    """The header (what, repeats, contention before and after, peak RSS, machine) and one markdown row per part."""
    print(f"\n{title}; median of {repeats} repeat(s); before: {before}; after: {contention()}; "
          f"peak RSS {peak_rss_mib():.0f} MiB\nmachine: {machine_line(machine_info(device))}")
    for note in notes:
        print(f"note: {note}")
    columns = COLUMNS[:-1] + list(extra_columns) + COLUMNS[-1:]
    print("\n| " + " | ".join(columns) + " |\n" + "|---" * len(columns) + "|")
    for r in rows:
        per = r.median / r.n if r.n else math.nan
        cells = [r.part, f"{r.median:.4g}", _cell(r.n), r.unit, _cell(per * 1000), _cell(1 / per if per else math.nan)]
        cells += [(r.extra or {}).get(c, "-") for c in extra_columns]
        print("| " + " | ".join([*cells, r.load]) + " |")
    sys.stdout.flush()
