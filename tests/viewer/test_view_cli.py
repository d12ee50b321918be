"""``livescene view``: start-up, and every refusal names the file, the problem and the fix."""

from __future__ import annotations

import re
import sys

import pytest

from stages.cli import available
from stages.viewer.cli import CPU_CHUNK_RAYS, main
from stages.viewer.viser_dependency import VISER_VERSION, install_command


def test_view_is_a_livescene_subcommand():
    assert available()["view"][0] == "stages.viewer.cli"


def test_without_viser_the_error_gives_the_pip_command(monkeypatch, capsys, viewer_scene):
    monkeypatch.setitem(sys.modules, "viser", None)  # what `import viser` sees when it is not installed
    assert main(["--run", str(viewer_scene.run_dir)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: viser: the live viewer needs the optional package viser, which is not installed")
    assert f'-m pip install "viser=={VISER_VERSION}"' in err and install_command() in err
    assert 'pip install -e ".[viewer]"' in err


@pytest.mark.parametrize(("args", "message"), [
    (["--resolution", "big"], r"--resolution: 'big' is not WIDTHxHEIGHT; fix: write e.g. --resolution 128x96"),
    (["--frame-budget", "0"], r"--frame-budget: 0.0 seconds; fix: give a positive number"),
    (["--settle", "-1"], r"--settle: -1.0 seconds; fix: give a positive number"),
    (["--threads", "0"], r"--threads: 0 threads; fix: give 1 or more"),
    # viser takes any socket error for a busy port and tries the next one without end: these hung without a word
    (["--port", "70000"], r"--port: 70000 is not a port; fix: give a port from 1 to 65535"),
    (["--port", "-1"], r"--port: -1 is not a port"),
    (["--host", "256.1.1.1"], r"--host: '256.1.1.1' is not an address of this machine"),
    (["--host", "192.0.2.1"], r"--host: cannot serve on '192.0.2.1' .*fix: give 127.0.0.1"),  # TEST-NET: not ours
])
def test_bad_options_are_refused(args, message, capsys, viewer_scene, monkeypatch):
    pytest.importorskip("viser")
    import stages.viewer.server as server

    def built_anyway(*_a, **_k):  # a refusal lost would otherwise serve (or retry ports) without end
        raise AssertionError(f"the viewer was started with {args}")

    monkeypatch.setattr(server, "LiveViewer", built_anyway)
    assert main(["--run", str(viewer_scene.run_dir), "--data", str(viewer_scene.data), *args]) == 2
    assert re.search(message, capsys.readouterr().err)


def test_a_missing_run_and_a_foreign_dataset_are_refused(capsys, tmp_path, viewer_scene, tiny_dataset):
    pytest.importorskip("viser")
    assert main(["--run", str(tmp_path / "nothing")]) == 2
    assert "run folder not found; fix: train one with `livescene train" in capsys.readouterr().err
    assert main(["--run", str(viewer_scene.run_dir), "--data", str(tiny_dataset.root), "--port", "0"]) == 2
    err = capsys.readouterr().err
    assert "mapping.yaml: objects ['object0', 'object1', 'object2'] differ from the run's ['cabinet', 'drawer']" in err
    assert "fix: pass the dataset the run was trained on with --data" in err


def test_the_viewer_finds_the_runs_language_table(monkeypatch, viewer_scene, bag_encoder):
    pytest.importorskip("viser")
    from stages.viewer.cli import build_parser, build_viewer

    monkeypatch.setattr("stages.viewer.cli.encoder_from_args", lambda args: bag_encoder)
    viewer = build_viewer(build_parser().parse_args(["--run", str(viewer_scene.run_dir), "--data",
                                                     str(viewer_scene.data), "--port", "0"]))
    try:
        assert viewer.language.renders_language and viewer.language.run_encoder == bag_encoder.name
        assert viewer.language.sources() == ["probs", "language", "language_objects"]
        viewer.language.check_source("language")  # queries embedded like the targets: accepted
        assert viewer.options.full_pixels == 128 * 96 and viewer.options.chunk_rays == CPU_CHUNK_RAYS
    finally:
        viewer.stop()


def test_the_viewer_starts_prints_its_address_and_stops(capsys, viewer_scene):
    pytest.importorskip("viser")
    code = main(["--run", str(viewer_scene.run_dir), "--data", str(viewer_scene.data), "--port", "0",
                 "--no-encoder", "--threads", "1", "--stop-after", "0.5"])
    out = capsys.readouterr().out
    assert code == 0
    assert re.search(r"livescene view: http://127\.0\.0\.1:\d+/ +\(2 objects: cabinet, drawer; full resolution "
                     r"12288 pixels; Ctrl-C stops\)", out)


def test_slider_hint_names_a_range_the_training_frames_do_not_span():
    from stages.scene.dataset import spans_closed_to_open
    from stages.viewer.server import slider_hint

    assert slider_hint("fridge", [0.0, 1.0]) == "state of fridge: 0 closed, 1 open"
    assert slider_hint("fridge", None) == "state of fridge: 0 closed, 1 open"  # learned states: no range
    assert slider_hint("drawer", [0.0, 0.5]).endswith("the training frames show 0.00 to 0.50 (beyond, the render "
                                                      "extrapolates)")
    assert spans_closed_to_open([0.1, 0.9]) and not spans_closed_to_open([0.2, 1.0])


def test_a_run_that_reads_no_state_says_so_beside_its_sliders(viewer_scene):
    """A k-planes run's images are the same at any state: its sliders and commands must not look as if they work."""
    pytest.importorskip("viser")
    from stages.language.vocabulary import ObjectVocabulary
    from stages.model.run import LoadedRun
    from stages.viewer.language_controls import LanguageControls
    from stages.viewer.server import LiveViewer, ViewerOptions

    class TimeOnly:  # the tiny run, seen as a k-planes run (its fourth axis the frame's time)
        reads_states = False
        STATES_UNREAD = LoadedRun.STATES_UNREAD

        def __getattr__(self, name):
            return getattr(viewer_scene.run, name)

    ds = viewer_scene.dataset
    language = LanguageControls(ObjectVocabulary.from_prompts(ds.objects, ds.prompts), None)
    viewer = LiveViewer(TimeOnly(), ds, language, ViewerOptions(port=0, full_pixels=32 * 24, verbose=False))
    try:
        assert "Not controllable:** a k-planes run reads no object state" in viewer.states_note.content
        viewer._run_command(f"open the {viewer_scene.visible}")
        assert f"{viewer_scene.visible} -> 1.00" in viewer.language_status.content
        assert "the image does not change: a k-planes run reads no object state" in viewer.language_status.content
    finally:
        viewer.stop()


def test_a_relevancy_query_that_names_nothing_says_so(live_viewer, viewer_scene):
    """The map of a query always lights up some object (a softmax): the status line says when it names none."""
    live_viewer._show_relevancy("xyzzy qwerty")
    assert "names no object of the scene" in live_viewer.language_status.content
    live_viewer._show_relevancy(viewer_scene.visible)
    assert "names no object" not in live_viewer.language_status.content
    live_viewer.show_colour()
