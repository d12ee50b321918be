"""Atomic writes: outputs appear complete or not at all.

A stage writes into a temporary sibling and renames it into place, so an
interrupted run never leaves a half-written file or folder that a later rule
would mistake for a finished one.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import shutil
import tempfile
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from .errors import InputError

STAGE_MARKER = ".livescene-stage"
"""Written into every stage output folder: the stage's name, so that only its own earlier output is replaced."""


def _current_umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _publish_mode(path: Path, *, directory: bool) -> None:
    """Give a temporary file or folder the mode a plain open()/mkdir() would have given it.

    mkstemp/mkdtemp create 0600/0700 entries so that nobody reads them half-written; the finished
    output must be readable by others (shared results folders, web servers showing the reports).
    """
    base = 0o777 if directory else 0o666
    path.chmod(base & ~_current_umask())


@contextlib.contextmanager
def atomic_path(path: str | Path, *, suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary file path next to ``path``; rename it onto ``path`` on success."""
    path = Path(path)
    if path.is_dir():
        raise InputError(path, "is a folder, and this output is a file", "give a file name (e.g. inside that folder)")
    path.parent.mkdir(parents=True, exist_ok=True)
    suffix = suffix or path.suffix or ".tmp"
    _remove_orphans(path, suffix=suffix)
    # the writer's pid in the name, as atomic_dir's: a later write can tell a killed run's leftover
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.{os.getpid()}.", suffix=suffix, dir=path.parent)
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        _publish_mode(tmp_path, directory=False)
        os.replace(tmp_path, path)
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    return True


def _remove_dead(folder: Path, pattern: re.Pattern[str], kind: str = "any") -> None:
    """Delete the entries of ``folder`` (``kind``: "dir", "file" or "any"; never a link) whose name ``pattern``
    matches with a writer's pid as its group 1, when that process is gone: no exit handler ran for them."""
    if not folder.is_dir():
        return
    with os.scandir(folder) as entries:
        dead = [e for e in entries if (m := pattern.match(e.name)) and int(m.group(1)) != os.getpid()
                and not e.is_symlink() and (kind != "dir" or e.is_dir(follow_symlinks=False))
                and (kind != "file" or e.is_file(follow_symlinks=False)) and not _alive(int(m.group(1)))]
    for entry in dead:
        if entry.is_dir(follow_symlinks=False):
            shutil.rmtree(entry.path, ignore_errors=True)
        else:
            Path(entry.path).unlink(missing_ok=True)


def _remove_orphans(path: Path, suffix: str | None = None) -> None:
    """Delete the temporary siblings of ``path`` that a killed run left (their writer's process is gone).

    A SIGTERM between ``mkdtemp`` and the swap leaves ``.<name>.<pid>.<random>`` behind (a video's frames: hundreds
    of MB), and one inside ``atomic_path`` a file ``.<name>.<pid>.<random><suffix>``; a live writer of the same
    output, which Snakemake never starts twice, keeps its own. ``suffix`` None: folders, else files.
    """
    tail = r"(?:old\.)?[a-z0-9_]{8}" if suffix is None else r"[a-z0-9_]{8}" + re.escape(suffix)
    _remove_dead(path.parent, re.compile(rf"^\.{re.escape(path.name)}\.(\d+)\.{tail}$"),
                 "dir" if suffix is None else "file")


_ANY_TEMPORARY = re.compile(r"^\..+\.(\d+)\.(?:old\.)?[a-z0-9_]{8}(?:\.[^.]+)?$")


def remove_dead_temporaries(folder: Path) -> None:
    """Delete every temporary of ``atomic_path`` / ``atomic_dir`` in ``folder`` whose writer is gone, whatever
    output it was for: a checkpoint a killed run was saving at a step that is never saved again would otherwise
    stay (its own name is never written again, so ``_remove_orphans`` never meets it)."""
    _remove_dead(folder, _ANY_TEMPORARY)


@contextlib.contextmanager
def scratch_folder(prefix: str) -> Iterator[Path]:
    """A temporary working folder in the system's temporary directory (``<prefix><pid>.<random>``), removed on exit;
    those a killed run of the same kind left (its process gone) are removed first, as no exit handler ran for them."""
    _remove_dead(Path(tempfile.gettempdir()), re.compile(rf"^{re.escape(prefix)}(\d+)\."), "dir")
    with tempfile.TemporaryDirectory(prefix=f"{prefix}{os.getpid()}.") as tmp:
        yield Path(tmp)


def _marker_stage(folder: Path) -> str | None:
    marker = folder / STAGE_MARKER
    try:
        return marker.read_text().strip() if marker.is_file() else None
    except OSError:
        return None


def _overlap(path: Path, inputs: Sequence[str | Path | None], *, folder: bool) -> str | None:
    """How ``path`` meets one of ``inputs`` (None: not given), or None: it is one, or, as a ``folder`` output that
    is replaced as a whole, holds one, or, as a file output, lies inside one (a run's weights, a dataset's images)."""
    target = path.resolve()
    for item in filter(None, inputs):
        src = Path(item).resolve()
        if src == target:
            return f"is the input {item}"
        if folder and target in src.parents:
            return f"holds the input {item}"
        if not folder and src in target.parents:
            return f"lies inside the input {item}"
    return None


def guard_output_dir(path: str | Path, stage: str, *, inputs: Sequence[str | Path | None] = (),
                     legacy: Sequence[str] = (), force: bool = False) -> None:
    """Refuse an output folder whose replacement would delete something that is not ``stage``'s own output.

    A stage's output folder is replaced as a whole, so ``path`` may only be absent, empty, or an earlier output
    of the same stage: it holds ``STAGE_MARKER`` naming ``stage`` (or, written before the marker existed, one of
    the ``legacy`` record files and no marker), or anything when the user asked for it (``force``, a CLI's
    ``--force``). It may never be one of the stage's ``inputs`` (None: an optional one not given) or a folder that
    holds one. Call it before long work, so that a bad ``--out`` fails at once; ``atomic_dir`` calls it again.
    """
    path = Path(path)
    found_input = _overlap(path, inputs, folder=True)
    if found_input is not None:
        raise InputError(path, f"{found_input}: the {stage} output replaces this folder as a whole",
                         "choose another --out, outside the inputs")
    if not path.exists() and not path.is_symlink():
        return
    if path.is_symlink():  # replacing it would drop the link and leave its target as it was: say so instead
        raise InputError(path, f"is a symbolic link; the {stage} stage writes a folder here",
                         "give the folder the link points to as --out, or another --out")
    if not path.is_dir():
        raise InputError(path, f"exists and is not a folder; the {stage} stage writes a folder here",
                         "choose another --out, or move that file away")
    if force or not any(path.iterdir()):
        return
    found = _marker_stage(path)
    if found == stage or (found is None and any((path / name).is_file() for name in legacy)):
        return
    held = f"the output of the {found} stage" if found else "files that are not an output of this stage"
    raise InputError(path, f"holds {held}; the {stage} output replaces this folder as a whole, which would delete "
                     "them", f"choose another --out (an empty or new folder, or an earlier {stage} output), or move "
                     "that folder away yourself")


def guard_output_file(path: str | Path, what: str, *, suffixes: Sequence[str],
                      inputs: Sequence[str | Path | None] = ()) -> None:
    """Refuse a single-file output that would overwrite something it should not: a file of another kind than
    ``suffixes`` (``--out run/model.pt`` for a PNG), one of the ``inputs`` (None: not given) or a file inside an
    input folder (a run's weights, a dataset's images). Call it before the work, so a bad ``--out`` fails at once."""
    path = Path(path)
    if path.suffix.lower() not in suffixes:
        raise InputError(path, f"is no {'/'.join(suffixes)} file name; {what} is written here",
                         f"give --out a name ending in {suffixes[0]}")
    found_input = _overlap(path, inputs, folder=False)
    if found_input is not None:
        raise InputError(path, f"{found_input}; writing {what} there would overwrite it or add to it",
                         "choose an --out outside the inputs")
    if path.is_dir():
        raise InputError(path, "is a folder, and this output is a file", "give a file name (e.g. inside that folder)")


@contextlib.contextmanager
def atomic_dir(path: str | Path, stage: str, *, inputs: Sequence[str | Path | None] = (),
               legacy: Sequence[str] = (), force: bool = False) -> Iterator[Path]:
    """Yield a temporary folder next to ``path``; swap it into place on success.

    An existing ``path`` is only replaced once the new content is complete, and only if ``guard_output_dir``
    allows it (checked before anything is written); the new folder carries ``STAGE_MARKER``.
    """
    path = Path(path)
    guard_output_dir(path, stage, inputs=inputs, legacy=legacy, force=force)
    path.parent.mkdir(parents=True, exist_ok=True)
    _remove_orphans(path)
    # the writer's pid in the name: a later run can tell a killed run's leftovers from a live one's work
    tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.{os.getpid()}.", dir=path.parent))
    try:
        yield tmp
        (tmp / STAGE_MARKER).write_text(stage + "\n")
        _publish_mode(tmp, directory=True)
        if path.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{path.name}.{os.getpid()}.old.", dir=path.parent))
            old.rmdir()
            os.replace(path, old)
            os.replace(tmp, path)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(tmp, path)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)


def write_text(path: str | Path, text: str) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def write_json(path: str | Path, data: Any) -> None:
    write_text(path, json.dumps(data, indent=2, sort_keys=False, default=_json_default) + "\n")


def write_yaml(path: str | Path, data: Any) -> None:
    write_text(path, yaml.safe_dump(data, sort_keys=False))


def write_npy(path: str | Path, array: np.ndarray) -> None:
    with atomic_path(path, suffix=".npy") as tmp:
        np.save(tmp, array)


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"cannot serialise {type(obj).__name__} to JSON")
