"""The building blocks of the pages against hand-computed values: cell formatting and escaping, images and error
maps, the inline SVG plots, the inputs manifest, the readers of the stage outputs and the index page."""

from __future__ import annotations

import base64
import math
import re

import cv2
import numpy as np
import pytest

from stages.report.html_parts import fmt, missing, page, table
from stages.report.images import error_map, file_data_uri, png_data_uri, read_rgb
from stages.report.index_page import build_index
from stages.report.inputs import inputs_from_mapping
from stages.report.scene_data import read_benchmark, state_errors_vs_truth
from stages.report.svg_plot import PALETTE, Series, bar_chart_svg, line_plot_svg, nice_ticks
from stages.scene import InputError

# -- cells and escaping ---------------------------------------------------------------------------------------------


def test_cells_say_yes_no_units_and_a_dash_for_no_number():
    assert (fmt(True), fmt(False)) == ("yes", "no")
    assert fmt(1234567, unit=" MiB") == "1,234,567 MiB"
    assert fmt(2.5, 2, " s") == "2.50 s"
    assert [fmt(v) for v in (None, float("nan"), float("inf"), -float("inf"))] == ["–"] * 4


def test_user_strings_are_escaped_in_cells_headers_notices_and_titles():
    assert fmt("<b>Tür & Tor</b>") == "&lt;b&gt;Tür &amp; Tor&lt;/b&gt;"
    html = table(["IoU <door>"], [[1.5]])
    assert "<th>IoU &lt;door&gt;</th>" in html and '<td class="num">1.500</td>' in html
    assert missing("rule <x> & y skipped") == '<p class="missing">rule &lt;x&gt; &amp; y skipped</p>'
    assert "<title>LiveScene report: a&lt;b&gt;</title>" in page("LiveScene report: a<b>", "")


# -- images ---------------------------------------------------------------------------------------------------------


def test_images_are_read_and_encoded_as_rgb(tmp_path):
    rgb = np.zeros((2, 3, 3), np.uint8)
    rgb[..., 0] = 200  # pure red
    cv2.imwrite(str(tmp_path / "red.png"), rgb[..., ::-1])  # cv2 writes BGR
    assert read_rgb(tmp_path / "red.png").tolist() == rgb.tolist()
    uri = png_data_uri(rgb)
    assert uri.startswith("data:image/png;base64,")
    decoded = cv2.imdecode(np.frombuffer(base64.b64decode(uri.split(",", 1)[1]), np.uint8), cv2.IMREAD_COLOR)
    assert decoded[..., ::-1].tolist() == rgb.tolist()
    assert read_rgb(tmp_path / "absent.png") is None


def test_file_data_uri_keeps_the_bytes_and_names_jpeg(tmp_path):
    (tmp_path / "a.JPG").write_bytes(b"\xff\xd8jpeg")
    (tmp_path / "b.png").write_bytes(b"\x89PNG")
    assert file_data_uri(tmp_path / "a.JPG") == "data:image/jpeg;base64," + base64.b64encode(b"\xff\xd8jpeg").decode()
    assert file_data_uri(tmp_path / "b.png") == "data:image/png;base64," + base64.b64encode(b"\x89PNG").decode()
    assert file_data_uri(tmp_path / "absent.png") is None


def test_error_map_is_black_at_zero_and_yellow_from_a_quarter():
    truth = np.zeros((1, 4, 3), np.uint8)
    render = np.zeros_like(truth)
    render[0, 1] = 32  # mean error 32/255 = 0.1255: 128/255 of the 0.25 scale
    render[0, 2] = 64  # 0.251: saturated
    render[0, 3] = 255  # 1.0: saturated too
    lut = cv2.applyColorMap(np.arange(256, dtype=np.uint8).reshape(1, 256), cv2.COLORMAP_INFERNO)[0, :, ::-1]
    out = error_map(truth, render)
    assert out.shape == (1, 4, 3)
    assert out[0, 0].tolist() == lut[0].tolist() and max(lut[0]) < 10  # black
    assert out[0, 1].tolist() == lut[128].tolist()
    assert out[0, 2].tolist() == out[0, 3].tolist() == lut[255].tolist()
    red, green, blue = (int(c) for c in out[0, 3])
    assert red > 240 and green > 240 and blue < 200  # yellow, in RGB order


# -- plots ----------------------------------------------------------------------------------------------------------


def test_nice_ticks():
    assert nice_ticks(0, 10) == [0, 2, 4, 6, 8, 10]  # a step of exactly (hi - lo) / 5 is taken
    assert nice_ticks(0, 300) == [0, 100, 200, 300]
    assert nice_ticks(-0.8, 10.8) == [0, 5, 10]
    assert nice_ticks(float("nan"), 1) == []


def _points(svg: str) -> list[str]:
    return re.findall(r'points="([^"]*)"', svg)


def test_line_plot_places_points_on_its_axes():
    """640 x 360 with margins 64 / 150 / 34 / 48: the plot area is x 64..490, y 34..312. x runs from 0 to 10;
    y from 0 - 0.8 to 10 + 0.8 (8 % padding), so y = 0 sits at 312 - 0.8 / 11.6 * 278 = 292.8 and y = 10 at 53.2."""
    svg = line_plot_svg([Series("m", [0.0, 10.0], [0.0, 10.0])], x_label="step", y_label="PSNR")
    assert _points(svg) == ["64.0,292.8 490.0,53.2"]
    # the x axis starts at 0 even when the first point is later: x = 5 is half way
    svg = line_plot_svg([Series("m", [5.0, 10.0], [0.0, 10.0])], x_label="step", y_label="PSNR")
    assert _points(svg) == ["277.0,292.8 490.0,53.2"]
    # a flat line is padded by 1 on each side: it sits in the middle, not on an edge
    svg = line_plot_svg([Series("m", [0.0, 10.0], [20.0, 20.0])], x_label="step", y_label="PSNR")
    assert _points(svg) == ["64.0,173.0 490.0,173.0"]


def test_line_plot_series_colours_legend_and_escaping():
    series = [
        Series("live<scene>", [0.0, 1.0], [1.0, 2.0]),
        Series("b", [0.0, 1.0], [2.0, 3.0]),
        Series("no data", [0.0], [float("nan")]),
    ]
    svg = line_plot_svg(series, x_label="x & y", y_label="y")
    assert re.findall(r'<polyline fill="none" stroke="([^"]+)"', svg) == PALETTE[:2]
    assert "live<scene>" not in svg and svg.count("live&lt;scene&gt;") == 2  # line tooltip and legend
    assert "x &amp; y" in svg
    assert "no data" not in svg  # a series without a finite point gets no line and no legend entry
    legend = re.findall(r'<text x="528" y="([0-9.]+)" font-size="12">', svg)
    assert legend == ["52", "70"]  # one legend row per series, 18 px apart
    assert "No data to plot for eval PSNR" in line_plot_svg([Series("m", [], [])], x_label="x", y_label="eval PSNR")


def test_bar_chart_scales_bars_to_the_longest():
    svg = bar_chart_svg([("train", 10.0), ("capture", 5.0)])
    # 640 wide, labels 170, 80 kept for the value: the longest bar is 390 px
    assert re.findall(r'<rect x="170" y="[0-9.]+" width="([0-9.]+)"', svg) == ["390.0", "195.0"]
    assert ">10.0 s<" in svg and ">5.0 s<" in svg


# -- the inputs manifest --------------------------------------------------------------------------------------------


def test_manifest_takes_null_as_absent_and_refuses_an_empty_path():
    inputs = inputs_from_mapping({"poses": None, "dataset": "d", "runs": {"livescene": "r/run.json"}})
    assert inputs.poses is None and str(inputs.dataset) == "d" and str(inputs.run_dir("livescene")) == "r"
    with pytest.raises(InputError, match="role 'poses' is '', not a path"):
        inputs_from_mapping({"poses": ""})
    with pytest.raises(InputError, match="not a mapping of method -> path"):
        inputs_from_mapping({"eval": {"livescene": ""}})


# -- readers --------------------------------------------------------------------------------------------------------


def test_a_benchmark_file_gives_its_last_row(tmp_path):
    (tmp_path / "b.tsv").write_text("s\tmax_rss\tcpu_time\tmean_load\n1.5\t10\t1.0\t0.5\n7.25\t20\tx\t0.7\n")
    values = read_benchmark(tmp_path / "b.tsv")
    assert values["s"] == 7.25 and values["max_rss"] == 20.0 and math.isnan(values["cpu_time"])
    (tmp_path / "empty.tsv").write_text("s\tmax_rss\n")
    assert read_benchmark(tmp_path / "empty.tsv") is None and read_benchmark(tmp_path / "absent.tsv") is None


def test_state_errors_against_the_truth_are_matched_by_frame(tmp_path):
    (tmp_path / "states.csv").write_text(
        "frame,object,value\na.png,door,0.5\nb.png,door,0.2\nc.png,door,0.9\na.png,lid,1.0\n"
    )
    # c.png has no truth: left out; the truth of d.png has no estimate
    (tmp_path / "truth.csv").write_text(
        "frame,object,value\na.png,door,0.25\nb.png,door,0.3\nd.png,door,0.0\na.png,lid,0.5\n"
    )
    errors = state_errors_vs_truth(tmp_path / "states.csv", tmp_path / "truth.csv")
    assert errors["door"] == {"mae": pytest.approx(0.175), "max": pytest.approx(0.25), "n": 2}
    assert errors["lid"] == {"mae": pytest.approx(0.5), "max": pytest.approx(0.5), "n": 1}


# -- the index page -------------------------------------------------------------------------------------------------


def _summary(scene: str, verdict: list[dict], **extra) -> dict:
    return {
        "scene": scene,
        "page": f"scenes/{scene}.html",
        "objects": ["Tür & Tor"],
        "frames": 80,
        "registered_fraction": 0.75,
        "methods": {},
        "verdict": verdict,
        "skipped": ["labels"],
        "job_seconds": 1234.4,
        **extra,
    }


def _verdict_row(verdict: str) -> dict:
    return {
        "livescene": "livescene",
        "baseline": "conerf",
        "metric": "held_out_psnr",
        "n": 8,
        "mean_difference": 1.0,
        "ci95": [0.5, 1.5],
        "verdict": verdict,
        "rests_on_flagged_run": [],
        "statement": verdict,
        "note": "",
    }


def test_index_rows_escape_names_and_show_each_scenes_own_numbers():
    html = build_index(
        [_summary("<kitchen>", [_verdict_row("LiveScene ahead")])],
        pending=["a<b"],
        earlier=[_summary("pantry", [_verdict_row("LiveScene behind")], built="2024-01-01 10:00 UTC")],
    )
    scenes = html.split("<h2>Scenes</h2>")[1].split("<h2>Pages from earlier runs</h2>")[0]
    assert '<a href="scenes/&lt;kitchen&gt;.html">&lt;kitchen&gt;</a>' in scenes and "<kitchen>" not in html
    assert "<td>Tür &amp; Tor</td>" in scenes
    assert "<td>75%</td>" in scenes and "<td>1234</td>" in scenes and "<td>labels</td>" in scenes
    assert "vs conerf: 1 ahead, 0 level, 0 behind" in scenes
    assert "a&lt;b" in scenes and "a<b" not in html
    earlier = html.split("<h2>Pages from earlier runs</h2>")[1]
    # an earlier page's counts are its own verdicts, kept out of the matrix above
    assert "vs conerf: 0 ahead, 0 level, 1 behind" in earlier and "2024-01-01 10:00 UTC" in earlier
