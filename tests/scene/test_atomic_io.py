"""Atomic writes: a finished output has the usual permissions, replaces the old one whole, and a
failure leaves the old output untouched."""

from __future__ import annotations

import os
import stat

import pytest

from stages.scene.atomic_io import atomic_dir, write_json


def _mode(path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


def test_outputs_get_umask_permissions_not_tempfile_ones(tmp_path):
    old = os.umask(0o022)
    try:
        write_json(tmp_path / "a.json", {"x": 1})
        with atomic_dir(tmp_path / "folder") as tmp:
            (tmp / "inside.txt").write_text("hi")
    finally:
        os.umask(old)
    assert _mode(tmp_path / "a.json") == 0o644
    assert _mode(tmp_path / "folder") == 0o755


def test_failed_write_keeps_the_previous_output(tmp_path):
    target = tmp_path / "folder"
    with atomic_dir(target) as tmp:
        (tmp / "v1.txt").write_text("one")
    with pytest.raises(RuntimeError), atomic_dir(target) as tmp:
        (tmp / "v2.txt").write_text("two")
        raise RuntimeError("interrupted")
    assert sorted(p.name for p in target.iterdir()) == ["v1.txt"]
    assert [p.name for p in tmp_path.iterdir()] == ["folder"]  # no temporary left behind
