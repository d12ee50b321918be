"""The stage CLIs' error wrapper: user errors become one line and an exit status, bugs keep their traceback."""

from __future__ import annotations

import os

import pytest

from stages.scene import InputError, SceneError
from stages.scene.cli_errors import EXIT_USER_ERROR, ErrorExit, cli_errors


class Diverged(RuntimeError):
    pass


@cli_errors(KeyError, ErrorExit(Diverged, 1, "training diverged: "))
def main(argv: list[str] | None = None) -> int:
    what = (argv or ["ok"])[0]
    if what == "input":
        raise SceneError("data/transforms.json", "no frames", "run the frames stage first")
    if what == "key":
        raise KeyError("unknown method 'nope'; use one of ['livescene']")
    if what == "diverged":
        raise Diverged("loss is NaN at step 3")
    if what == "bug":
        raise ZeroDivisionError("a bug")
    return 0


def test_a_user_error_prints_its_message_and_returns_the_exit_code_without_traceback(capsys):
    assert main(["input"]) == EXIT_USER_ERROR == 2
    captured = capsys.readouterr()
    assert captured.err == "error: data/transforms.json: no frames; fix: run the frames stage first\n"
    assert "Traceback" not in captured.err and captured.out == ""


def test_extra_types_get_their_own_code_prefix_and_text(capsys):
    assert main(["key"]) == 2
    assert capsys.readouterr().err == "error: unknown method 'nope'; use one of ['livescene']\n"  # no KeyError quotes
    assert main(["diverged"]) == 1
    assert capsys.readouterr().err == "error: training diverged: loss is NaN at step 3\n"


def test_an_unexpected_error_is_not_swallowed(capsys):
    with pytest.raises(ZeroDivisionError, match="a bug"):
        main(["bug"])
    assert capsys.readouterr().err == ""


def test_success_and_the_wrapped_function_are_unchanged():
    assert main([]) == 0 and main.__name__ == "main" and main.__wrapped__.__name__ == "main"


def test_only_the_listed_types_are_caught(capsys):
    @cli_errors()
    def plain(kind: type[Exception]) -> int:
        raise kind("boom", "problem", "fix") if issubclass(kind, InputError) else kind("boom")

    assert plain(SceneError) == 2 and "error: boom: problem; fix: fix" in capsys.readouterr().err
    with pytest.raises(ValueError):
        plain(ValueError)  # InputError is a ValueError, but not every ValueError is a user error
    with pytest.raises(FileNotFoundError):
        plain(FileNotFoundError)


def test_value_errors_can_be_reported_where_a_cli_asks_for_it(capsys):
    @cli_errors(ValueError)
    def lenient() -> int:
        raise ValueError("bad split fraction")

    assert lenient() == 2 and capsys.readouterr().err == "error: bad split fraction\n"


def test_misuse_without_parentheses_is_refused_at_import():
    with pytest.raises(TypeError, match=r"@cli_errors\(\)"):
        cli_errors(main)  # type: ignore[arg-type]


def test_ctrl_c_ends_in_one_line_and_status_130(capsys):
    @cli_errors()
    def main() -> int:
        raise KeyboardInterrupt

    assert main() == 130
    err = capsys.readouterr().err
    assert err.startswith("interrupted: ") and "Traceback" not in err and len(err.splitlines()) == 1


def test_a_full_disk_or_a_read_only_folder_is_said_with_the_output_it_was_for(capsys):
    import errno

    def failing(err: int, filename: str):
        @cli_errors()
        def main() -> int:
            raise OSError(err, os.strerror(err), filename)

        return main

    assert failing(errno.ENOSPC, "out/.frames.4242.abcd1234/images/frame_00005.png")() == 2
    err = capsys.readouterr().err
    assert err.startswith("error: out/frames: No space left on device; fix: free disk space there")
    assert failing(errno.EACCES, "ro/.metrics.json.77.wxyz5678.json")() == 2
    assert capsys.readouterr().err.startswith("error: ro/metrics.json: Permission denied; fix: choose an --out in")
    with pytest.raises(FileNotFoundError):  # any other OSError is a bug's or a crash's: its traceback stays
        failing(errno.ENOENT, "x")()


def test_sigterm_unwinds_an_atomic_write_where_asked(tmp_path, capsys):
    """A cancelled workflow job gets SIGTERM: a command that asks for it cleans up its hidden temporary as after
    Ctrl-C (with the default action the process died and left it until the next run)."""
    import signal

    from stages.scene import atomic_dir
    from stages.scene.cli_errors import EXIT_TERMINATED

    out = tmp_path / "export"

    @cli_errors(sigterm=True)
    def main() -> int:
        with atomic_dir(out, "export") as tmp:
            (tmp / "half.ply").write_text("partial")
            os.kill(os.getpid(), signal.SIGTERM)
        return 0

    assert main() == EXIT_TERMINATED
    assert "terminated: this command's output was not written" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []  # neither the output nor its temporary
    assert signal.getsignal(signal.SIGTERM) == signal.SIG_DFL  # the default action is back afterwards
