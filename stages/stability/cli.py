"""``livescene stability``: run the numerical-stability, guard, bad-input and interrupted-run checks.

Prints the table ``case | result | metric`` and writes a JSON summary (the
report includes it). The checks are pytest tests shipped in this package
(stages/stability/checks), run through pytest wherever the package is
installed; only the check that dry-runs the workflow needs a checkout
(--workflow). Exit status: 0 when no case failed or crashed
(skipped cases are listed with the reason, e.g. no GPU, or no --workflow for
the check that dry-runs the workflow), 1 otherwise, 2 for an unknown case
name or a run that could not start.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .collector import GROUPS
from .suite import format_markdown, format_table, run_suite


def build_parser(prog: str = "livescene stability") -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=prog, description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", type=Path, help="write the JSON summary here (e.g. results/stability/summary.json)")
    p.add_argument("--quick", action="store_true", help="fewer steps and frames (what the test suite runs)")
    p.add_argument("--case", action="append", default=[], metavar="NAME", help="run only this case (repeatable)")
    p.add_argument("--group", action="append", default=[], choices=GROUPS, help="run only this group (repeatable)")
    p.add_argument("--list", action="store_true", help="list the cases and what each checks, then exit")
    p.add_argument("--markdown", action="store_true", help="print the table as Markdown (for docs and reports)")
    p.add_argument("--workdir", type=Path, help="keep the scratch files here (default: a temporary folder)")
    p.add_argument("--threads", type=int, default=1, help="torch CPU threads (default 1)")
    p.add_argument("--workflow", type=Path, metavar="PATH",
                   help="a checkout of the workflow (the folder holding Snakefile, workflow/ and config/): "
                        "enables bad_workflow_config_wrong_type, which dry-runs a copy of it (default: skipped)")
    p.add_argument("--captures", type=Path, metavar="DIR",
                   help="folder of capture presets (stiff.yaml, stress.yaml, ...) to render instead of the "
                        "package's presets (config/captures of the checkout it was built from)")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    run = run_suite(args.case, args.group, quick=args.quick, workdir=args.workdir, threads=args.threads,
                    workflow=args.workflow, captures=args.captures, collect_only=args.list)
    if run.error:
        print(f"error: {run.error}", file=sys.stderr)
        return 2
    # 5: nothing selected; anything else but 0 and 1 (collection failed, interrupted, internal error): pytest said why
    if run.exit_code not in (0, 1, 5):
        print(f"error: the stability checks did not run (pytest exit status {run.exit_code}; see above)",
              file=sys.stderr)
        return 2
    if args.list:
        for c in run.collected:
            print(f"{c['name']} [{c['group']}]: {c['checks']}")
        return 0
    summary = run.summary
    print(format_markdown(summary["cases"]) if args.markdown else format_table(summary["cases"]))
    c = summary["counts"]
    print(f"\n{c['pass']} passed, {c['fail']} failed, {c['error']} errors, {c['skip']} skipped "
          f"of {len(summary['cases'])} cases in {summary['seconds']} s")
    if args.out:
        from stages.scene import write_json  # atomic (temp file + rename); imported only when needed

        write_json(args.out, summary)
        print(f"summary: {args.out}")
    return 0 if c["fail"] == 0 and c["error"] == 0 else 1


__all__ = ["build_parser", "main"]
