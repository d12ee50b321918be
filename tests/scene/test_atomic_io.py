"""Atomic writes: a finished output has the usual permissions, replaces the old one whole, a failure leaves
the old output untouched, and a folder that is not the same stage's output (or is an input) is never replaced."""

from __future__ import annotations

import json
import os
import stat

import pytest

from stages.scene import InputError
from stages.scene.atomic_io import STAGE_MARKER, atomic_dir, guard_output_dir, write_json


def _mode(path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


def test_outputs_get_umask_permissions_not_tempfile_ones(tmp_path):
    old = os.umask(0o022)
    try:
        write_json(tmp_path / "a.json", {"x": 1})
        with atomic_dir(tmp_path / "folder", "test") as tmp:
            (tmp / "inside.txt").write_text("hi")
    finally:
        os.umask(old)
    assert _mode(tmp_path / "a.json") == 0o644
    assert _mode(tmp_path / "folder") == 0o755


def test_failed_write_keeps_the_previous_output(tmp_path):
    target = tmp_path / "folder"
    with atomic_dir(target, "test") as tmp:
        (tmp / "v1.txt").write_text("one")
    with pytest.raises(RuntimeError), atomic_dir(target, "test") as tmp:
        (tmp / "v2.txt").write_text("two")
        raise RuntimeError("interrupted")
    assert sorted(p.name for p in target.iterdir()) == [STAGE_MARKER, "v1.txt"]
    assert [p.name for p in tmp_path.iterdir()] == ["folder"]  # no temporary left behind


def test_an_earlier_output_of_the_same_stage_is_replaced(tmp_path):
    target = tmp_path / "frames"
    for text in ("one", "two"):
        with atomic_dir(target, "frames") as tmp:
            (tmp / "frames.json").write_text(text)
    assert (target / "frames.json").read_text() == "two"
    assert (target / STAGE_MARKER).read_text().strip() == "frames"


def test_a_folder_of_other_files_is_refused_and_kept(tmp_path):
    target = tmp_path / "mine"
    target.mkdir()
    (target / "thesis.txt").write_text("precious")
    with pytest.raises(InputError, match=r"not an output of this stage.*fix: choose another --out"), \
            atomic_dir(target, "frames") as tmp:
        (tmp / "frames.json").write_text("{}")
    assert [p.name for p in target.iterdir()] == ["thesis.txt"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mine"]


def test_another_stages_output_is_refused(tmp_path):
    run = tmp_path / "run"
    with atomic_dir(run, "evaluate") as tmp:
        (tmp / "metrics.json").write_text("{}")
    with pytest.raises(InputError, match="holds the output of the evaluate stage"):
        guard_output_dir(run, "render")


def test_an_output_of_older_code_is_known_by_its_record_file(tmp_path):
    old = tmp_path / "labels"
    old.mkdir()
    (old / "labels.json").write_text("{}")
    guard_output_dir(old, "labels", legacy=["labels.json"])  # replaced, as before the marker existed
    with pytest.raises(InputError):
        guard_output_dir(old, "states", legacy=["states.json"])


def test_an_input_or_a_folder_holding_one_is_refused(tmp_path):
    source = tmp_path / "captures" / "room"
    source.mkdir(parents=True)
    (source / "video.mp4").write_bytes(b"x")
    with pytest.raises(InputError, match="is the input"):
        guard_output_dir(source, "frames", inputs=[source])
    with pytest.raises(InputError, match="holds the input"):
        guard_output_dir(tmp_path / "captures", "states", inputs=[source / "video.mp4"])
    guard_output_dir(source / "frames", "frames", inputs=[source])  # a new folder inside an input is fine


def test_a_file_or_a_link_in_the_way_is_refused(tmp_path):
    (tmp_path / "out").write_text("x")
    with pytest.raises(InputError, match="is not a folder"):
        guard_output_dir(tmp_path / "out", "frames")
    (tmp_path / "real").mkdir()
    (tmp_path / "link").symlink_to(tmp_path / "real")
    with pytest.raises(InputError, match="is a symbolic link"):
        guard_output_dir(tmp_path / "link", "frames")


def test_a_file_output_that_names_a_folder_is_refused(tmp_path):
    (tmp_path / "adir").mkdir()
    with pytest.raises(InputError, match="is a folder, and this output is a file"):
        write_json(tmp_path / "adir", {"x": 1})
    assert list((tmp_path / "adir").iterdir()) == []


def test_a_killed_runs_temporary_folder_is_removed_by_the_next_run(tmp_path):
    import subprocess
    import sys

    gone = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    dead = int(gone.stdout)
    orphan = tmp_path / f".frames.{dead}.abcd1234"  # what a SIGTERM before the swap leaves
    (orphan / "images").mkdir(parents=True)
    (orphan / "images" / "frame_00000.png").write_bytes(b"x" * 1000)
    live = tmp_path / f".frames.{os.getppid()}.wxyz5678"  # another writer, still running
    live.mkdir()
    mine = tmp_path / ".frames.backup"  # the user's own, whatever its name says
    mine.mkdir()
    with atomic_dir(tmp_path / "frames", "frames") as tmp:
        (tmp / "frames.json").write_text("{}")
    assert not orphan.exists() and live.is_dir() and mine.is_dir()
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([live.name, mine.name, "frames"])


def test_a_killed_runs_temporary_file_is_removed_by_the_next_write(tmp_path):
    import subprocess
    import sys

    gone = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    dead = int(gone.stdout)
    orphan = tmp_path / f".metrics.json.{dead}.abcd1234.json"  # what a SIGTERM inside atomic_path leaves
    orphan.write_text("{")
    live = tmp_path / f".metrics.json.{os.getppid()}.wxyz5678.json"  # another writer, still running
    live.write_text("{")
    other = tmp_path / f".other.json.{dead}.abcd1234.json"  # a temporary of another output: not this write's
    other.write_text("{")
    folder = tmp_path / f".metrics.json.{dead}.abcd9999.json"  # a folder of that name is nobody's temporary file
    folder.mkdir()
    write_json(tmp_path / "metrics.json", {"psnr": 1.0})
    assert not orphan.exists() and live.is_file() and other.is_file() and folder.is_dir()
    assert json.loads((tmp_path / "metrics.json").read_text()) == {"psnr": 1.0}
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([live.name, other.name, folder.name, "metrics.json"])


def test_dead_writers_temporaries_of_any_name_are_removed(tmp_path):
    import subprocess
    import sys

    from stages.scene.atomic_io import remove_dead_temporaries

    gone = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    dead = int(gone.stdout)
    half = tmp_path / f".step_000155.pt.{dead}.abcd1234.pt"  # a checkpoint a killed run was saving
    half.write_bytes(b"PK")
    live = tmp_path / f".step_000200.pt.{os.getppid()}.wxyz5678.pt"  # another writer, still running
    live.write_bytes(b"PK")
    kept = [tmp_path / "step_000100.pt", tmp_path / ".hidden", tmp_path / ".notes.txt"]
    for path in kept:
        path.write_bytes(b"x")
    remove_dead_temporaries(tmp_path)
    remove_dead_temporaries(tmp_path / "absent")  # no folder: nothing to do
    assert not half.exists() and live.exists() and all(p.exists() for p in kept)


def test_a_killed_runs_scratch_folder_is_removed_by_the_next_one(tmp_path, monkeypatch):
    import subprocess
    import sys
    import tempfile

    from stages.scene.atomic_io import scratch_folder

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    gone = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    left = tmp_path / f"livescene-triangulate-{int(gone.stdout)}.abcd1234"  # SIGKILL: no exit handler ran
    (left / "images").mkdir(parents=True)
    other = tmp_path / f"livescene-triangulate-{os.getppid()}.wxyz5678"  # a live run's
    other.mkdir()
    with scratch_folder("livescene-triangulate-") as work:
        assert work.is_dir() and work.name.startswith(f"livescene-triangulate-{os.getpid()}.")
        assert not left.exists() and other.is_dir()
    assert not work.exists()
