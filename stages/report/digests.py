"""Per-stage digests of a scene's results: where two runs of the same job part (docs/workflow.md, "Where two runs
part").

The job is bit-reproducible on one machine and gives other floats on another CPU ("Machines" there): the capture
renderer and COLMAP pick code paths by CPU, and training amplifies the last bit. A digest per stage output, in
pipeline order, shows at which stage two machines' (or two commits') results first differ: ``diff`` the
``digests.csv`` of two runs (``livescene report index --digests``) and the first differing row is that stage.

A stage's digest is SHA-256 over its result files in sorted relative-path order (code point order of the POSIX
path), each file's path, size and bytes hashed; the page shows the first 12 hex digits. Left out is what records
time, machine, load or absolute paths rather than the result, decided file by file from three fresh clones'
results of the default job on one machine (the same results; these files differed between them):

- hidden files (``.livescene-stage``, ``.snakemake_timestamp``): markers of a finished job, not results;
- a run's ``checkpoints/`` (resume state, the final weights are ``model.pt``; their run.json copy has the wall
  time) and ``train_log.csv`` (``wall_s`` and ``rays_per_s`` columns);
- an evaluation's ``timings.json`` (render seconds and fps);
- JSON files digested without some keys (``JSON_KEYS_LEFT_OUT``): capture.json and frames.json ``timings``,
  frames.json ``source`` (the video's absolute path), poses.json ``timings`` and ``motion_precheck.seconds``,
  run.json ``train_seconds``, ``peak_memory_*``, ``machine`` and ``code_digest`` (the code, not the result: it
  differs between commits that give the same bits). Such a file is hashed as canonical JSON (sorted keys, no
  spaces) without those keys; one that does not parse is hashed as it is.

Logs and Snakemake benchmarks are no stage's output and are never read here. Files are hashed in chunks of 1 MiB.
"""

from __future__ import annotations

import csv
import fnmatch
import hashlib
import io
import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from stages.scene import InputError

from .inputs import ReportInputs

SHOWN_HEX = 12
"""Hex digits of the SHA-256 shown on the page and written to digests.csv."""
CHUNK = 1 << 20


@dataclass(frozen=True)
class StageRule:
    """What of a stage's output folder is left out of its digest."""

    left_out: tuple[str, ...] = ()
    """fnmatch patterns of relative POSIX paths left out (``checkpoints/*`` is the folder)."""
    json_keys: dict[str, tuple[str, ...]] = field(default_factory=dict)
    """relative path -> dotted keys removed before the file is hashed as canonical JSON."""


RUN_JSON_LEFT_OUT = (
    "train_seconds",
    "peak_memory_mib",
    "peak_memory_kind",
    "peak_reserved_mib",
    "machine",
    "code_digest",
)
RULES: dict[str, StageRule] = {
    "capture": StageRule(json_keys={"capture.json": ("timings",)}),
    "frames": StageRule(json_keys={"frames.json": ("timings", "source")}),
    "poses": StageRule(json_keys={"poses.json": ("timings", "motion_precheck.seconds")}),
    "run": StageRule(left_out=("checkpoints/*", "train_log.csv"), json_keys={"run.json": RUN_JSON_LEFT_OUT}),
    "eval": StageRule(left_out=("timings.json",)),
}
"""Per kind of stage (``run`` and ``eval`` per method); a stage not named here is digested whole."""

SINGLE_STAGES = ("capture", "frames", "poses", "labels", "states", "dataset", "language", "exposure")
"""Roles of the report inputs manifest digested, in pipeline order (``language``: the language targets)."""

CSV_COLUMNS = ["scene", "stage", "files", "digest"]


@dataclass(frozen=True)
class StageDigest:
    """One stage output's digest; ``digest`` is None where the manifest's path does not exist."""

    stage: str
    path: Path
    files: int
    digest: str | None
    left_out: str

    def to_dict(self) -> dict:
        return {"stage": self.stage, "files": self.files, "digest": self.digest}


def _left_out_text(rule: StageRule) -> str:
    """What the digest leaves out, in words (hidden files are always left out)."""
    parts = [p.removesuffix("/*") + "/" if p.endswith("/*") else p for p in rule.left_out]
    parts += [f"{name} without {', '.join(keys)}" for name, keys in rule.json_keys.items()]
    return "; ".join(parts)


def _files(path: Path) -> list[tuple[str, Path]]:
    """(relative POSIX path, file) under ``path`` (hidden names left out), or the file itself by its name."""
    if path.is_file():
        return [(path.name, path)]
    out = []
    for folder, dirs, names in os.walk(path):
        dirs[:] = [d for d in dirs if not d.startswith(".")]
        for name in names:
            if name.startswith("."):
                continue
            file = Path(folder, name)
            if file.is_file():
                out.append((file.relative_to(path).as_posix(), file))
    return sorted(out)


def _drop_keys(data: object, keys: tuple[str, ...]) -> object:
    for dotted in keys:
        *parents, last = dotted.split(".")
        node = data
        for key in parents:
            node = node.get(key) if isinstance(node, dict) else None
        if isinstance(node, dict):
            node.pop(last, None)
    return data


def _hash_file(h: Any, rel: str, file: Path, keys: tuple[str, ...] | None) -> None:
    try:
        if keys is not None:
            raw = file.read_bytes()
            try:
                data = _drop_keys(json.loads(raw), keys)
                raw = json.dumps(data, sort_keys=True, separators=(",", ":"), ensure_ascii=False).encode()
            except (ValueError, UnicodeDecodeError):
                pass  # not JSON: its bytes as they are (another file than the other run's, and so another digest)
            h.update(f"{rel}\0{len(raw)}\0".encode())
            h.update(raw)
            return
        h.update(f"{rel}\0{file.stat().st_size}\0".encode())
        with file.open("rb") as handle:
            while chunk := handle.read(CHUNK):
                h.update(chunk)
    except OSError as exc:
        raise InputError(
            file,
            f"is not readable for the stage digests ({exc})",
            "re-run the rule that writes it, or fix the file's permissions",
        ) from exc


def digest_path(path: Path, rule: StageRule = StageRule()) -> tuple[int, str | None]:
    """(files covered, SHA-256 hex) of a stage output folder or file; (0, None) where it does not exist."""
    path = Path(path)
    if not path.exists():
        return 0, None
    h = hashlib.sha256()
    count = 0
    for rel, file in _files(path):
        if any(fnmatch.fnmatchcase(rel, pattern) for pattern in rule.left_out):
            continue
        _hash_file(h, rel, file, rule.json_keys.get(rel))
        count += 1
    return count, h.hexdigest()


def stage_digests(inputs: ReportInputs, methods: list[str]) -> list[StageDigest]:
    """The digest of every stage output the manifest names, in pipeline order: the single stages, then each
    method's run, then each method's evaluation."""
    entries: list[tuple[str, str, Path]] = [
        (role, role, getattr(inputs, role)) for role in SINGLE_STAGES if getattr(inputs, role) is not None
    ]
    entries += [(f"run/{m}", "run", inputs.run_dir(m)) for m in methods if inputs.run_dir(m) is not None]
    entries += [(f"eval/{m}", "eval", inputs.eval[m]) for m in methods if m in inputs.eval]
    out = []
    for stage, kind, path in entries:
        rule = RULES.get(kind, StageRule())
        files, digest = digest_path(path, rule)
        out.append(
            StageDigest(
                stage=stage, path=path, files=files, digest=digest and digest[:SHOWN_HEX], left_out=_left_out_text(rule)
            )
        )
    return out


def digests_csv(summaries: list[dict]) -> str:
    """digests.csv of the scenes' summaries: one row per (scene, stage), in the summaries' and pipeline order."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(CSV_COLUMNS)
    for s in summaries:
        for d in s.get("digests") or []:
            writer.writerow([s.get("scene"), d.get("stage"), d.get("files"), d.get("digest") or ""])
    return buffer.getvalue()
