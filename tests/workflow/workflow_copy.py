"""Helpers of the workflow tests: a private copy of the workflow (so runs never touch the repository's
results/ or .snakemake/), scene sheets written at test time, and a helper that runs Snakemake."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[2]
COLUMNS = ["scene", "source", "path", "poses", "masks", "key_frames", "names", "prompts", "truth", "methods",
           "state_ranges", "camera"]


@dataclass
class SnakemakeRun:
    code: int
    output: str

    def jobs(self) -> dict[str, int]:
        """The 'Job stats' table of a (dry) run: rule -> job count."""
        counts: dict[str, int] = {}
        block = self.output.split("Job stats:", 1)
        if len(block) < 2:
            return counts
        for line in block[1].splitlines()[3:]:
            m = re.match(r"^(\S+)\s+(\d+)$", line.strip())
            if not m:
                break
            if m.group(1) != "total":
                counts[m.group(1)] = int(m.group(2))
        return counts


    def blocks(self) -> list[tuple[str, str]]:
        """(rule, text) of every job printed by a dry run (text holds its wildcards and shell command)."""
        parts = re.split(r"^(?:local)?rule (\S+):$", self.output, flags=re.M)
        return [(parts[i], parts[i + 1]) for i in range(1, len(parts) - 1, 2)]

    def scene_jobs(self, scene: str) -> dict[str, list[str]]:
        """rule -> job texts of one scene (jobs whose wildcards name it)."""
        found: dict[str, list[str]] = {}
        for rule, text in self.blocks():
            if re.search(rf"wildcards: .*\bscene={re.escape(scene)}\b", text):
                found.setdefault(rule, []).append(text)
        return found


class WorkflowCopy:
    """Snakefile + workflow/ + config/ copied into a folder, with its own scene sheet and config."""

    def __init__(self, root: Path) -> None:
        self.root = root
        root.mkdir(parents=True, exist_ok=True)
        for part in ("Snakefile", "workflow", "config"):
            src = REPO / part
            (shutil.copytree if src.is_dir() else shutil.copy2)(src, root / part)

    def write_scenes(self, rows: list[dict[str, str]]) -> Path:
        lines = ["\t".join(COLUMNS)] + ["\t".join(str(r.get(c, "")) for c in COLUMNS) for r in rows]
        path = self.root / "config" / "scenes.tsv"
        path.write_text("\n".join(lines) + "\n")
        return path

    def write_config(self, **overrides) -> Path:
        config = yaml.safe_load((self.root / "config" / "config.yaml").read_text())
        config.update(overrides)
        path = self.root / "config" / "test-config.yaml"
        path.write_text(yaml.safe_dump(config))
        return path

    def snakemake(self, *args: str, timeout: float = 600) -> SnakemakeRun:
        done = subprocess.run([sys.executable, "-m", "snakemake", *args], cwd=self.root, capture_output=True,
                              text=True, timeout=timeout)
        return SnakemakeRun(done.returncode, done.stdout + done.stderr)

    def dry_run(self, *args: str) -> SnakemakeRun:
        # The default profile prints the shell commands (printshellcmds), which the tests read. No target is
        # named: the plan is what `snakemake --cores 2` at the repository root builds.
        run = self.snakemake("-n", "--cores", "2", "--workflow-profile", "workflow/profiles/default", *args)
        assert run.code == 0, run.output[-3000:]
        return run
