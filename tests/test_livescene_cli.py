"""The `livescene` dispatcher: one subcommand per built stage, each with working --help."""

from __future__ import annotations

import subprocess
import sys

import pytest

from stages.cli import COMMANDS, available, main


def test_help_lists_only_available_commands(capsys):
    assert main(["--help"]) == 0
    out = capsys.readouterr().out
    for name in COMMANDS:
        assert (f"  {name} " in out) == (name in available()), name


def test_unknown_command_fails_cleanly(capsys):
    assert main(["no-such-stage"]) == 2
    assert "unknown command" in capsys.readouterr().err


@pytest.mark.parametrize("name", sorted(available()))
def test_each_command_has_help(name):
    code = f"from stages.cli import main; raise SystemExit(main([{name!r}, '--help']))"
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "usage:" in proc.stdout


@pytest.mark.parametrize("package", sorted({m.split(".")[1] for m, _ in available().values()}))
def test_python_dash_m_stage_help(package):
    proc = subprocess.run([sys.executable, "-m", f"stages.{package}", "--help"], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "usage:" in proc.stdout
