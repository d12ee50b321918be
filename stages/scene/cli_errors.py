"""One way every stage CLI reports the project's own errors: a message on stderr, an exit status, no traceback.

An ``InputError`` (stages/scene/errors.py) already says which file is wrong and how to fix it, so a
traceback would only bury that line; the workflow's logs and a person at a terminal both read
``error: <file>: <problem>; fix: <fix>`` and exit status 2. So is what the machine refuses (a full disk, a
folder one may not write to), and Ctrl-C ends with one line and status 130. Anything else is a bug or a crash
and keeps its traceback: the wrapper never catches it.

    @cli_errors()
    def main(argv: list[str] | None = None) -> int: ...

    @cli_errors(ValueError)                                   # also report ValueError as a user error
    @cli_errors(ErrorExit(TrainingDiverged, 1, "training diverged: "))   # another status and a prefix
"""

from __future__ import annotations

import contextlib
import errno
import functools
import re
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import ParamSpec

from .errors import InputError

EXIT_USER_ERROR = 2
"""Exit status of a CLI refusing its input (argparse uses 2 for bad arguments too)."""

EXIT_INTERRUPTED = 130
"""Exit status after Ctrl-C (128 + SIGINT, as a shell reports it)."""
SYSTEM_FIXES = {
    errno.ENOSPC: "free disk space there, or choose an --out on another disk",
    errno.EDQUOT: "free space in your quota, or choose an --out elsewhere",
    errno.EACCES: "choose an --out in a folder you may write to",
    errno.EPERM: "choose an --out in a folder you may write to",
    errno.EROFS: "choose an --out on a writable disk",
}
"""What the machine refuses (a full disk, a folder one may not write to), said as such with its fix."""
_TEMPORARY = re.compile(r"^\.(.+)\.\d+\.(?:old\.)?[a-z0-9_]{8}(?:\.[^.]*)?$")

P = ParamSpec("P")


def output_of(filename: str | None) -> str:
    """The output a failed write was for: a path inside an atomic write's hidden temporary (``.frames.123.abcd1234``)
    named by the output it was to become (``frames``)."""
    if not filename:
        return "the output"
    parts = list(Path(str(filename)).parts)
    for i, part in enumerate(parts):
        if m := _TEMPORARY.match(part):
            return str(Path(*parts[:i], m.group(1)))
    return str(filename)


@dataclass(frozen=True)
class ErrorExit:
    """One more exception type a CLI reports as a message rather than a traceback."""

    kind: type[Exception]
    code: int = EXIT_USER_ERROR
    """Exit status returned for it."""
    prefix: str = ""
    """Put before the exception's text, after ``error: ``."""


class Terminated(KeyboardInterrupt):
    """SIGTERM (a scheduler, or Snakemake cancelling a job), raised where the program is, so that an atomic write
    unwinds as after Ctrl-C: with the default action the process dies at once and leaves its hidden temporary."""


EXIT_TERMINATED = 143
"""Exit status after SIGTERM (128 + 15)."""


@contextlib.contextmanager
def sigterm_as_interrupt() -> Iterator[None]:
    """While inside, SIGTERM raises ``Terminated`` (main thread, default action only). Only for commands whose
    work returns to Python often (torch ops): a handler waits for a long C call to return, where the default
    action would not (COLMAP's mapping is left to it)."""
    if threading.current_thread() is not threading.main_thread() or signal.getsignal(signal.SIGTERM) != signal.SIG_DFL:
        yield
        return

    def raise_terminated(_signum: int, _frame: object) -> None:
        raise Terminated

    signal.signal(signal.SIGTERM, raise_terminated)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, signal.SIG_DFL)


def cli_errors(*also: type[Exception] | ErrorExit,
               sigterm: bool = False) -> Callable[[Callable[P, int]], Callable[P, int]]:
    """Decorate a CLI ``main``: ``InputError`` (and each of ``also``) -> ``error: ...`` on stderr and its code.

    The first matching entry wins, ``InputError`` first. A ``KeyError`` prints its message without the
    quotes ``str(KeyError)`` adds. ``sigterm``: SIGTERM unwinds as Ctrl-C does (``sigterm_as_interrupt``).
    """
    exits = [ErrorExit(InputError), *(a if isinstance(a, ErrorExit) else ErrorExit(a) for a in also)]
    for e in exits:
        if not (isinstance(e.kind, type) and issubclass(e.kind, Exception)):
            raise TypeError(f"cli_errors takes exception types or ErrorExit, got {e.kind!r}; write @cli_errors()")
    kinds = tuple(e.kind for e in exits)

    def wrap(main: Callable[P, int]) -> Callable[P, int]:
        @functools.wraps(main)
        def run(*args: P.args, **kwargs: P.kwargs) -> int:
            try:
                with sigterm_as_interrupt() if sigterm else contextlib.nullcontext():
                    return main(*args, **kwargs)
            except kinds as exc:
                rule = next(e for e in exits if isinstance(exc, e.kind))
                print(f"error: {rule.prefix}{message(exc)}", file=sys.stderr)
                return rule.code
            except KeyboardInterrupt as exc:  # Ctrl-C: outputs are written atomically, nothing half-written is left
                what = "terminated" if isinstance(exc, Terminated) else "interrupted"
                print(f"{what}: this command's output was not written (an earlier one is kept as it was); run "
                      "it again to redo the work", file=sys.stderr)
                return EXIT_TERMINATED if isinstance(exc, Terminated) else EXIT_INTERRUPTED
            except OSError as exc:
                if exc.errno not in SYSTEM_FIXES:
                    raise
                print(f"error: {output_of(exc.filename)}: {exc.strerror}; fix: {SYSTEM_FIXES[exc.errno]}",
                      file=sys.stderr)
                return EXIT_USER_ERROR

        run.unwinds_sigterm = sigterm  # type: ignore[attr-defined]  # read by a test over every command
        return run

    return wrap


def message(exc: BaseException) -> str:
    """The text of ``exc`` as a user should read it."""
    if isinstance(exc, KeyError) and exc.args:
        return str(exc.args[0])
    return str(exc)
