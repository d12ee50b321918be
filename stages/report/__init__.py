"""Report: state sweeps for the sliders and the self-contained HTML pages (index + one per scene).

A scene page reads only the stage outputs its report inputs manifest names (inputs.py), wherever they
lie, and embeds every image as a data URI, so a page opens offline, alone, from any folder.
"""

from .index_page import build_index
from .inputs import ReportInputs, read_inputs
from .scene_data import SceneData, collect_scene
from .scene_page import build_scene_page
from .svg_plot import Series, line_plot_svg
from .sweep import render_sweeps

__all__ = [
    "ReportInputs",
    "SceneData",
    "Series",
    "build_index",
    "build_scene_page",
    "collect_scene",
    "line_plot_svg",
    "read_inputs",
    "render_sweeps",
]
