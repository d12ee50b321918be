"""The viewer's status lines are viser markdown, which renders raw HTML unsanitised (to every client) and markdown
syntax: an object name or a typed command was written into them as it is, so "<b>drawer" was bold, an <img onerror>
tag in a command ran in every connected browser, and "kid_s *big* drawer" lost its stars."""

from __future__ import annotations

from types import SimpleNamespace

from stages.language.commands import parse_command
from stages.viewer.server import LiveViewer, md_text

NAMES = ['kid_s *big* <b>drawer</b>', "шкаф"]


def test_a_command_and_its_object_names_are_shown_as_text():
    shown = SimpleNamespace(content="")
    viewer = SimpleNamespace(language=SimpleNamespace(encoder_loaded=True), reads_states=True,
                             language_status=shown, apply_command=lambda text: parse_command(text, NAMES))
    LiveViewer._run_command(viewer, "open the kid_s *big* <b>drawer</b> <img src=x onerror=alert(1)>")
    assert "<b>" not in shown.content and "<img" not in shown.content, shown.content
    assert r"kid\_s \*big\* &lt;b>drawer&lt;/b> -> 1.00" in shown.content
    assert md_text("шкаф: drawer-2 (left) [a] & b") == r"шкаф: drawer-2 (left) \[a\] &amp; b"
