"""``livescene stability``: run the numerical-stability, guard, bad-input and interrupted-run cases.

Prints the table ``case | result | metric`` and writes a JSON summary (the
report includes it). Exit status: 0 when no case failed or crashed (skipped
cases are listed with the reason, e.g. no GPU), 1 otherwise.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from stages.scene import write_json

from .case_registry import CASES, GROUPS
from .suite import format_markdown, format_table, run_suite, select


def build_parser(prog: str = "livescene stability") -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=prog, description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", type=Path, help="write the JSON summary here (e.g. results/stability/summary.json)")
    p.add_argument("--quick", action="store_true", help="fewer steps and frames (what the pytest suite runs)")
    p.add_argument("--case", action="append", default=[], metavar="NAME", help="run only this case (repeatable)")
    p.add_argument("--group", action="append", default=[], choices=GROUPS, help="run only this group (repeatable)")
    p.add_argument("--list", action="store_true", help="list the cases and what each checks, then exit")
    p.add_argument("--markdown", action="store_true", help="print the table as Markdown (for docs and reports)")
    p.add_argument("--workdir", type=Path, help="keep the scratch files here (default: a temporary folder)")
    p.add_argument("--threads", type=int, default=1, help="torch CPU threads (default 1)")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        cases = select(args.case, args.group)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if args.list:
        for c in cases:
            print(f"{c.name} [{c.group}]: {c.checks}")
        return 0

    def progress(row) -> None:
        print(f"  {row.name}: {row.result} ({row.seconds:.1f} s)", file=sys.stderr, flush=True)

    summary = run_suite(cases, quick=args.quick, workdir=args.workdir, threads=args.threads, on_result=progress)
    print(format_markdown(summary["cases"]) if args.markdown else format_table(summary["cases"]))
    c = summary["counts"]
    print(f"\n{c['pass']} passed, {c['fail']} failed, {c['error']} errors, {c['skip']} skipped "
          f"of {len(summary['cases'])} cases in {summary['seconds']} s")
    if args.out:
        write_json(args.out, summary)
        print(f"summary: {args.out}")
    return 0 if c["fail"] == 0 and c["error"] == 0 else 1


__all__ = ["CASES", "build_parser", "main"]
