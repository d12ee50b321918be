"""Everything a scene page shows, read from the files the stages wrote under results/<scene>/.

Each reader returns None (or an empty container) when its file is absent, so a page can say which
rule was skipped instead of breaking.
"""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from stages.scene import InputError


def _read_text_file(path: Path, parse: Any, what: str, errors: tuple[type[Exception], ...]) -> Any:
    """``parse`` of a file's text, or None when absent; a corrupt file is an input error naming it."""
    if not path.is_file():
        return None
    try:
        return parse(path.read_text())
    except (OSError, *errors) as exc:
        raise InputError(path, f"is not readable {what} ({exc})", "re-run the rule that writes it") from exc


def read_json(path: Path) -> Any:
    """A JSON file, or None when absent; a corrupt file is an input error naming it."""
    return _read_text_file(path, json.loads, "JSON", (json.JSONDecodeError,))


def read_csv_rows(path: Path) -> list[dict[str, str]]:
    if not path.is_file():
        return []
    with path.open(newline="") as handle:
        return list(csv.DictReader(handle))


def read_benchmarks(folder: Path) -> dict[str, dict[str, float]]:
    """Snakemake benchmark TSVs (s, max_rss, cpu_time, ...) by rule name (file stem)."""
    out: dict[str, dict[str, float]] = {}
    if not folder.is_dir():
        return out
    for path in sorted(folder.glob("*.tsv")):
        with path.open(newline="") as handle:
            rows = list(csv.DictReader(handle, delimiter="\t"))
        if not rows:
            continue
        values: dict[str, float] = {}
        for key in ("s", "max_rss", "cpu_time", "mean_load"):
            try:
                values[key] = float(rows[-1].get(key, "nan"))
            except ValueError:
                values[key] = float("nan")
        out[path.stem] = values
    return out


def csv_number(value: str | None) -> float | None:
    """A CSV cell as a number; None for an empty or non-numeric cell."""
    try:
        return float(value) if value not in (None, "") else None
    except ValueError:
        return None


def train_curve(path: Path, axis: str = "wall_s") -> tuple[list[float], list[float], list[float], list[float]]:
    """(x, eval_psnr) where evaluated, and (x, loss) of every logged step, from train_log.csv; x is ``axis``.

    ``axis`` "wall_s" plots error against run time; "step" against steps, the fair axis once every method
    trains the same steps (wall time also measures the machine and its load).
    """
    xs, ps, lx, ls = [], [], [], []
    for row in read_csv_rows(path):
        x = csv_number(row.get(axis))
        if x is None:
            continue
        psnr, loss = csv_number(row.get("eval_psnr")), csv_number(row.get("loss"))
        if psnr is not None:
            xs.append(x)
            ps.append(psnr)
        if loss is not None:
            lx.append(x)
            ls.append(loss)
    return xs, ps, lx, ls


def train_curve_by_step(path: Path) -> tuple[list[float], list[float], list[float], list[float]]:
    """``train_curve`` against steps."""
    return train_curve(path, "step")


def read_yaml(path: Path) -> Any:
    """A YAML file, or None when absent; a corrupt file is an input error naming it."""
    import yaml

    return _read_text_file(path, yaml.safe_load, "YAML", (yaml.YAMLError,))


def state_errors_vs_truth(states_csv: Path, truth_csv: Path) -> dict[str, dict[str, float]]:
    """Per object: MAE / max of the interpolated states against the truth (matched on frame file name)."""
    pred = {(r["frame"], r["object"]): float(r["value"]) for r in read_csv_rows(states_csv)}
    truth = {(r["frame"], r["object"]): float(r["value"]) for r in read_csv_rows(truth_csv)}
    per: dict[str, list[float]] = {}
    for key, value in pred.items():
        if key in truth:
            per.setdefault(key[1], []).append(abs(value - truth[key]))
    return {obj: {"mae": sum(v) / len(v), "max": max(v), "n": len(v)} for obj, v in per.items() if v}


@dataclass
class MethodData:
    """One trained method: its run and its evaluation."""

    name: str
    run: dict | None = None
    """run.json of the run (None when training did not finish)."""
    curve: tuple[list[float], list[float], list[float], list[float]] = ([], [], [], [])
    """train_log.csv as (wall_s, eval_psnr, wall_s, loss)."""
    step_curve: tuple[list[float], list[float], list[float], list[float]] = ([], [], [], [])
    """train_log.csv as (step, eval_psnr, step, loss)."""
    config: dict | None = None
    """config.yaml of the run (a RunConfig dict; its ``trust`` section sets the trust floors)."""
    metrics: dict | None = None
    """metrics.json of the evaluation."""
    timings: dict | None = None
    """timings.json of the evaluation (render seconds, fps): wall-clock numbers kept out of metrics.json."""
    eval_dir: Path | None = None
    sweep: dict | None = None
    """sweep.json of the state sweep (None when no sweep was rendered)."""
    sweep_dir: Path | None = None
    control: dict | None = None
    """language-command results of the control rule."""


@dataclass
class SceneData:
    """The measured numbers and images of one scene."""

    scene: str
    results: Path
    data: Path | None
    truth: Path | None
    plan: dict[str, dict]
    benchmarks: dict[str, dict[str, float]]
    capture: dict | None = None
    frames: dict | None = None
    poses: dict | None = None
    pose_error: dict | None = None
    labels: dict | None = None
    states: dict | None = None
    states_vs_truth: dict[str, dict[str, float]] = field(default_factory=dict)
    dataset_info: dict | None = None
    methods: list[MethodData] = field(default_factory=list)
    stability: dict | None = None


def collect_scene(scene: str, results: str | Path, *, data: str | Path | None, truth: str | Path | None,
                  methods: list[str], plan: dict[str, dict], stability: str | Path | None = None) -> SceneData:
    """Read every file of results/<scene>/ the page uses."""
    root = Path(results)
    truth_dir = Path(truth) if truth else None
    sd = SceneData(scene=scene, results=root, data=Path(data) if data else None, truth=truth_dir, plan=plan,
                   benchmarks=read_benchmarks(root / "benchmarks"))
    sd.capture = read_json(root / "capture" / "capture.json")
    sd.frames = read_json(root / "frames" / "frames.json")
    sd.poses = read_json(root / "poses" / "poses.json")
    sd.pose_error = read_json(root / "pose_error.json")
    sd.labels = read_json(root / "labels" / "labels.json")
    sd.states = read_json(root / "states" / "states.json")
    if truth_dir is not None and (root / "states" / "states.csv").is_file():
        sd.states_vs_truth = state_errors_vs_truth(root / "states" / "states.csv", truth_dir / "truth" / "states.csv")
    if sd.data is not None and (sd.data / "transforms.json").is_file():
        transforms = read_json(sd.data / "transforms.json") or {}
        frames = transforms.get("frames", [])
        mapping_file = sd.data / "mapping.yaml"
        import yaml

        mapping = yaml.safe_load(mapping_file.read_text()) if mapping_file.is_file() else {}
        sd.dataset_info = {"frames": len(frames),
                           "train": sum(1 for f in frames if f.get("split") == "train"),
                           "test": sum(1 for f in frames if f.get("split") == "test"),
                           "width": transforms.get("w"), "height": transforms.get("h"),
                           "objects": [str(mapping[k]) for k in sorted(mapping)] if mapping else []}
    for name in methods:
        m = MethodData(name=name)
        run_dir = root / "runs" / name
        m.run = read_json(run_dir / "run.json")
        m.curve = train_curve(run_dir / "train_log.csv")
        m.step_curve = train_curve_by_step(run_dir / "train_log.csv")
        m.config = read_yaml(run_dir / "config.yaml")
        eval_dir = root / "eval" / name
        m.metrics = read_json(eval_dir / "metrics.json")
        m.timings = read_json(eval_dir / "timings.json")
        m.eval_dir = eval_dir if eval_dir.is_dir() else None
        sweep_dir = root / "sweep" / name
        m.sweep = read_json(sweep_dir / "sweep.json")
        m.sweep_dir = sweep_dir if m.sweep else None
        m.control = read_json(root / "control" / name / "commands.json")
        sd.methods.append(m)
    if stability:
        sd.stability = read_json(Path(stability))
        shared = read_benchmarks(Path(stability).parent)  # the suite runs once for all scenes
        if "benchmark" in shared:
            sd.benchmarks["stability"] = shared["benchmark"]
    return sd
