"""The report inputs manifest: which file or folder fills each role of a scene page.

The page is told where every input is (``livescene report scene --inputs FILE``) instead of guessing a
folder layout, so it renders the same from a workflow's results or from files put anywhere by hand. The
manifest is a JSON (or YAML, by suffix) mapping; relative paths are read from the current directory, like
every path option of the CLI. A role left out means its stage did not run for the scene (docs/workflow.md,
"The report").
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

from stages.scene import InputError

SINGLE_ROLES = {
    "dataset": "scene dataset folder (transforms.json, mapping.yaml, the truth images of the grid)",
    "truth": "folder holding truth/ (truth/states.csv: the dense truth states)",
    "capture": "capture folder (capture.json)",
    "frames": "frames folder (frames.json)",
    "poses": "poses folder (poses.json)",
    "pose_error": "JSON of `livescene poses compare` (estimated poses against the truth)",
    "labels": "labels folder (labels.json, propagation.json, confidence.csv)",
    "states": "states folder (states.json, states.csv)",
    "language": "language targets (the page reads grounding from the evaluations; digested with the other stages)",
    "exposure": "exposure.json of the scene's exposure measurement",
    "stability": "summary.json of `livescene stability`",
    "stability_benchmark": "benchmark TSV of the stability suite",
    "benchmarks": "folder of the scene's benchmark TSVs (one per job, named after it)",
    "logs": "folder of the scene's job logs (only named in the page's hints)",
}
METHOD_ROLES = {
    "runs": "method -> run folder of `livescene train`, or its run.json",
    "eval": "method -> evaluation folder (metrics.json, timings.json, renders/, grounding/)",
    "sweep": "method -> state sweep folder (sweep.json and its images)",
    "control": "method -> language command folder (commands.json and its renders)",
    "export": "method -> export folder of `livescene export` (export.json, meshes, thumbnails)",
}
FIX = "write it as docs/workflow.md describes (section 'The report')"


@dataclass(frozen=True)
class ReportInputs:
    """Where each input of a scene page is; None (or no entry) where the stage did not run."""

    dataset: Path | None = None
    truth: Path | None = None
    capture: Path | None = None
    frames: Path | None = None
    poses: Path | None = None
    pose_error: Path | None = None
    labels: Path | None = None
    states: Path | None = None
    language: Path | None = None
    exposure: Path | None = None
    stability: Path | None = None
    stability_benchmark: Path | None = None
    benchmarks: Path | None = None
    logs: Path | None = None
    runs: dict[str, Path] = field(default_factory=dict)
    eval: dict[str, Path] = field(default_factory=dict)
    sweep: dict[str, Path] = field(default_factory=dict)
    control: dict[str, Path] = field(default_factory=dict)
    export: dict[str, Path] = field(default_factory=dict)

    def methods(self) -> list[str]:
        """Methods named by any per-method role, in order of first mention."""
        seen: dict[str, None] = {}
        for role in METHOD_ROLES:
            seen.update(dict.fromkeys(getattr(self, role)))
        return list(seen)

    def run_dir(self, method: str) -> Path | None:
        """The run folder of ``method``: the role may name the folder or its run.json."""
        path = self.runs.get(method)
        if path is None:
            return None
        return path.parent if path.suffix == ".json" else path

    def to_dict(self) -> dict[str, Any]:
        """The manifest mapping (paths as strings; absent roles left out)."""
        out: dict[str, Any] = {}
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, dict):
                if value:
                    out[f.name] = {k: str(v) for k, v in value.items()}
            elif value is not None:
                out[f.name] = str(value)
        return out


def inputs_from_mapping(mapping: Any, where: str | Path = "report inputs") -> ReportInputs:
    """Check a manifest mapping (roles as in SINGLE_ROLES and METHOD_ROLES) and turn it into ReportInputs."""
    if not isinstance(mapping, dict):
        raise InputError(where, f"is {type(mapping).__name__}, not a mapping of role -> path", FIX)
    unknown = sorted(set(mapping) - set(SINGLE_ROLES) - set(METHOD_ROLES))
    if unknown:
        raise InputError(where, f"unknown role(s) {unknown}", f"use only {sorted({*SINGLE_ROLES, *METHOD_ROLES})}")
    values: dict[str, Any] = {}
    for role, value in mapping.items():
        if role in METHOD_ROLES:
            if not isinstance(value, dict) or not all(isinstance(k, str) and _is_path(v) for k, v in value.items()):
                raise InputError(where, f"role {role!r} is {value!r}, not a mapping of method -> path", FIX)
            values[role] = {k: Path(v) for k, v in value.items()}
        elif value is not None:
            if not _is_path(value):
                raise InputError(where, f"role {role!r} is {value!r}, not a path", FIX)
            values[role] = Path(value)
    return ReportInputs(**values)


def _is_path(value: Any) -> bool:
    return isinstance(value, str) and value != ""


def read_inputs(path: str | Path) -> ReportInputs:
    """The manifest file at ``path`` (YAML for .yaml / .yml, else JSON)."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise InputError(path, f"report inputs manifest not readable ({exc})", FIX) from exc
    if path.suffix.lower() in (".yaml", ".yml"):
        import yaml

        try:
            mapping = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            raise InputError(path, f"is not YAML ({exc})", FIX) from exc
    else:
        try:
            mapping = json.loads(text)
        except json.JSONDecodeError as exc:
            raise InputError(path, f"is not JSON ({exc})", FIX) from exc
    return inputs_from_mapping(mapping, path)
