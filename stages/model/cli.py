"""``python -m stages.model train|render ...``: the same commands as ``livescene train`` / ``livescene render``."""

from __future__ import annotations

import sys

from . import render_cli, train_cli

USAGE = "usage: python -m stages.model {train,render} [options]  (see `... train --help`)"


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if not argv or argv[0] in ("-h", "--help"):
        print(USAGE)
        return 0
    commands = {"train": train_cli.main, "render": render_cli.main}
    if argv[0] not in commands:
        print(f"error: unknown command {argv[0]!r}\n{USAGE}", file=sys.stderr)
        return 2
    return commands[argv[0]](argv[1:])
