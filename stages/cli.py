"""``livescene <stage> ...``: one console script, one subcommand per stage.

A subcommand exists only when its stage package is installed in this tree,
so nothing answers "not implemented". Each stage's ``cli.main(argv)`` does the
work; ``python -m stages.<name>`` calls the same function.
"""

from __future__ import annotations

import importlib
import os
import sys
import warnings
from pathlib import Path

# subcommand -> (module holding main(argv), one-line help)
COMMANDS: dict[str, tuple[str, str]] = {
    "capture": ("stages.capture.cli", "generate a synthetic interactive-room capture with ground truth"),
    "frames": ("stages.frames.cli", "extract frames (with source index and sharpness) from a video"),
    "poses": ("stages.poses.cli", "estimate camera poses with COLMAP (pycolmap)"),
    "labels": ("stages.labels.cli", "ingest object masks in any supported format"),
    "states": ("stages.states.cli", "interpolate key-frame interaction variables to every frame"),
    "scene": ("stages.scene.cli", "validate and inspect scene datasets"),
    "dataset": ("stages.dataset.cli", "assemble frames, poses, labels and states into a scene dataset"),
    "train": ("stages.model.train_cli", "train LiveScene or a baseline on a scene dataset"),
    "render": ("stages.model.render_cli", "render any pose with any object states from a trained run"),
    "export": ("stages.export.cli", "mesh and point cloud of a trained run at chosen object states"),
    "compare": ("stages.compare.cli", "train every method for the same wall-clock budget"),
    "evaluate": ("stages.evaluate.cli", "metrics, unseen-state control and grounding for a trained run"),
    "language": ("stages.language.cli", "text encoder, language targets and relevancy queries"),
    "control": ("stages.language.control_cli", "set object states from language commands"),
    "report": ("stages.report.cli", "write the self-contained HTML report"),
    "stability": ("stages.stability.cli", "run the numerical-stability suite and print its table"),
    "view": ("stages.viewer.cli", "live browser viewer: object sliders, language commands, relevancy (viser)"),
}

# (command, subcommand) -> the (command, subcommand) it now runs: old spellings kept for the scripts that use them.
# `scene assemble` moved to the dataset stage, since stages.scene may import no stage that runs after it; the
# callers of the old name are listed in docs/data-contract.md ("Scene dataset").
ALIASES: dict[tuple[str, str], tuple[str, str]] = {("scene", "assemble"): ("dataset", "assemble")}


def module_file_exists(module: str) -> bool:
    """Whether ``stages.x.y`` has its source file here, without importing ``stages.x`` (torch is slow to load)."""
    root = Path(__file__).resolve().parent
    parts = module.split(".")[1:]
    return (root.joinpath(*parts).with_suffix(".py")).is_file() or (root.joinpath(*parts) / "__init__.py").is_file()


def available() -> dict[str, tuple[str, str]]:
    return {name: entry for name, entry in COMMANDS.items() if module_file_exists(entry[0])}


def usage(commands: dict[str, tuple[str, str]]) -> str:
    width = max(len(n) for n in commands) if commands else 0
    lines = ["usage: livescene <command> [options]", "", "commands:"]
    lines += [f"  {n.ljust(width)}  {h}" for n, (_, h) in commands.items()]
    lines += ["", "`livescene <command> --help` describes each command."]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    commands = available()
    if not argv or argv[0] in ("-h", "--help"):
        print(usage(commands))
        return 0
    name, rest = argv[0], argv[1:]
    if rest and (name, rest[0]) in ALIASES:
        name, sub = ALIASES[name, rest[0]]
        rest = [sub, *rest[1:]]
    if name not in commands:
        print(f"livescene: unknown command {name!r}\n\n{usage(commands)}", file=sys.stderr)
        return 2
    use_passive_openmp_wait()
    warnings.formatwarning = _one_line_warning
    from stages.scene.cli_errors import cli_errors  # here, not at the top: `livescene --help` stays fast

    # Ctrl-C while a command (or its imports) runs: one line, for commands without their own wrapper too
    return cli_errors()(_run_command)(commands[name][0], rest)


def _run_command(module_name: str, argv: list[str]) -> int:
    module = importlib.import_module(module_name)
    return int(module.main(argv) or 0)


def _one_line_warning(message: Warning | str, category: type[Warning], filename: str, lineno: int,
                      line: str | None = None) -> str:
    """A warning as a CLI says it: ``warning: <text>`` (the project's warnings name the file and the fix), not
    Python's source location and line."""
    return f"warning: {message}\n" if issubclass(category, UserWarning) else \
        f"{filename}:{lineno}: {category.__name__}: {message}\n"


def use_passive_openmp_wait() -> None:
    """Let torch's OpenMP threads sleep at barriers instead of spinning, unless the user chose otherwise.

    Must run before torch loads. With the default spin policy a 2-thread training step on a 2-core machine
    that runs anything else took 2.52 s instead of 0.45 s (5.6x) and burnt six times the CPU time
    (docs/model.md, "OpenMP wait policy"); the workflow's jobs always share their cores with each other.
    """
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")


if __name__ == "__main__":
    raise SystemExit(main())
