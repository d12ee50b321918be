"""Everything a scene page shows, read from the stage outputs the report inputs manifest names (inputs.py).

Each reader returns None (or an empty container) when its file is absent, so a page can say which
rule was skipped instead of breaking. Inside a stage's output the file names are that stage's own
(run.json, metrics.json, ...); where the outputs lie is only known from the manifest.
"""

from __future__ import annotations

import csv
import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from stages.scene import InputError

from .digests import StageDigest, stage_digests
from .inputs import ReportInputs


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


def read_benchmark(path: Path) -> dict[str, float] | None:
    """The last row of one Snakemake benchmark TSV (s, max_rss, cpu_time, mean_load); None when absent or empty."""
    if not path.is_file():
        return None
    with path.open(newline="") as handle:
        rows = list(csv.DictReader(handle, delimiter="\t"))
    if not rows:
        return None
    values: dict[str, float] = {}
    for key in ("s", "max_rss", "cpu_time", "mean_load"):
        try:
            values[key] = float(rows[-1].get(key, "nan"))
        except ValueError:
            values[key] = float("nan")
    return values


def benchmark_stem(rule: str) -> str:
    """The benchmark file stem of a plan entry: 'train[conerf]' -> 'train_conerf'."""
    return re.sub(r"\[(.*)\]", r"_\1", rule)


def read_benchmarks(folder: Path) -> dict[str, dict[str, float]]:
    """Snakemake benchmark TSVs (s, max_rss, cpu_time, ...) by rule name (file stem)."""
    out: dict[str, dict[str, float]] = {}
    if not folder.is_dir():
        return out
    for path in sorted(folder.glob("*.tsv")):
        values = read_benchmark(path)
        if values is not None:
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
    run_dir: Path | None = None
    """The run folder (its config.yaml is named in the trust flag)."""
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
    control_dir: Path | None = None
    """The folder of commands.json, which holds the command renders too."""


@dataclass
class SceneData:
    """The measured numbers and images of one scene."""

    scene: str
    plan: dict[str, dict]
    benchmarks: dict[str, dict[str, float]]
    inputs: ReportInputs = field(default_factory=ReportInputs)
    """Where each input was read from (the manifest)."""
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
    digests: list[StageDigest] = field(default_factory=list)
    """Per stage output, the SHA-256 of its result files (digests.py): where two runs of the job part."""

    @property
    def data(self) -> Path | None:
        """The scene dataset (truth images and object names)."""
        return self.inputs.dataset

    @property
    def truth(self) -> Path | None:
        """The folder holding truth/."""
        return self.inputs.truth


def _in(folder: Path | None, name: str) -> Path | None:
    """``folder / name``, or None when the role is absent."""
    return None if folder is None else folder / name


def _json_in(folder: Path | None, name: str) -> Any:
    path = _in(folder, name)
    return None if path is None else read_json(path)


def _dataset_info(data: Path) -> dict | None:
    """Frame counts, image size and object names of the dataset; None without transforms.json."""
    if not (data / "transforms.json").is_file():
        return None
    transforms = read_json(data / "transforms.json") or {}
    frames = transforms.get("frames", [])
    mapping_file = data / "mapping.yaml"
    import yaml

    mapping = yaml.safe_load(mapping_file.read_text()) if mapping_file.is_file() else {}
    return {"frames": len(frames),
            "train": sum(1 for f in frames if f.get("split") == "train"),
            "test": sum(1 for f in frames if f.get("split") == "test"),
            "width": transforms.get("w"), "height": transforms.get("h"),
            "objects": [str(mapping[k]) for k in sorted(mapping)] if mapping else [],
            "state_ranges": _training_state_ranges(data)}


def _training_state_ranges(data: Path) -> dict[str, list[float] | None]:
    """Per object, [min, max] of its state over the training frames; {} where the dataset does not read."""
    from stages.scene import SceneError, read_scene

    try:
        ds = read_scene(data, validate=False)
    except (SceneError, InputError):
        return {}
    return ds.state_ranges()


def collect_method(name: str, inputs: ReportInputs) -> MethodData:
    """Read the run, evaluation, sweep and commands of one method from the folders the manifest names."""
    m = MethodData(name=name, run_dir=inputs.run_dir(name))
    if m.run_dir is not None:
        m.run = read_json(m.run_dir / "run.json")
        m.curve = train_curve(m.run_dir / "train_log.csv")
        m.step_curve = train_curve_by_step(m.run_dir / "train_log.csv")
        m.config = read_yaml(m.run_dir / "config.yaml")
    eval_dir = inputs.eval.get(name)
    if eval_dir is not None:
        m.metrics = read_json(eval_dir / "metrics.json")
        m.timings = read_json(eval_dir / "timings.json")
        m.eval_dir = eval_dir if eval_dir.is_dir() else None
    sweep_dir = inputs.sweep.get(name)
    m.sweep = _json_in(sweep_dir, "sweep.json")
    m.sweep_dir = sweep_dir if m.sweep else None
    m.control_dir = inputs.control.get(name)
    m.control = _json_in(m.control_dir, "commands.json")
    return m


def collect_scene(scene: str, inputs: ReportInputs, *, methods: list[str] | None = None,
                  plan: dict[str, dict]) -> SceneData:
    """Read every input of the page from where ``inputs`` says it is; ``methods`` defaults to the manifest's."""
    benchmarks = read_benchmarks(inputs.benchmarks) if inputs.benchmarks else {}
    if plan:  # the jobs of this plan only: a method dropped from the row, or the page's own earlier build, left theirs
        planned = {benchmark_stem(rule) for rule, entry in plan.items() if entry.get("needed")}
        benchmarks = {stem: v for stem, v in benchmarks.items() if stem in planned}
    sd = SceneData(scene=scene, plan=plan, inputs=inputs, benchmarks=benchmarks)
    sd.capture = _json_in(inputs.capture, "capture.json")
    sd.frames = _json_in(inputs.frames, "frames.json")
    sd.poses = _json_in(inputs.poses, "poses.json")
    sd.pose_error = read_json(inputs.pose_error) if inputs.pose_error else None
    sd.labels = _json_in(inputs.labels, "labels.json")
    sd.states = _json_in(inputs.states, "states.json")
    states_csv = _in(inputs.states, "states.csv")
    if inputs.truth is not None and states_csv is not None and states_csv.is_file():
        sd.states_vs_truth = state_errors_vs_truth(states_csv, inputs.truth / "truth" / "states.csv")
    if inputs.dataset is not None:
        sd.dataset_info = _dataset_info(inputs.dataset)
    sd.methods = [collect_method(name, inputs) for name in (inputs.methods() if methods is None else methods)]
    if inputs.stability:
        sd.stability = read_json(inputs.stability)
    if inputs.stability_benchmark:  # the suite runs once for all scenes: its timing is listed with the scene's
        shared = read_benchmark(inputs.stability_benchmark)
        if shared is not None:
            sd.benchmarks["stability"] = shared
    sd.digests = stage_digests(inputs, [m.name for m in sd.methods])
    return sd
