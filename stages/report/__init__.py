"""Report: state sweeps for the sliders and the self-contained HTML pages (index + one per scene).

The pages read only the files the other stages write (results/<scene>/...) and embed every image
as a data URI, so a page opens offline, alone, from any folder.
"""

from .index_page import build_index
from .scene_data import SceneData, collect_scene
from .scene_page import build_scene_page
from .svg_plot import Series, line_plot_svg
from .sweep import render_sweeps

__all__ = [
    "SceneData",
    "Series",
    "build_index",
    "build_scene_page",
    "collect_scene",
    "line_plot_svg",
    "render_sweeps",
]
