"""Render sizes: --resolution as a pixel budget fitted to the client's aspect, and preview sizes."""

from __future__ import annotations

import pytest

from stages.scene import InputError
from stages.viewer.resolution import MIN_SIDE, Resolution, fit_to_aspect, preview_pixels


def test_parse_reads_width_by_height_and_names_the_fix():
    assert Resolution.parse("128x96") == Resolution(128, 96)
    assert Resolution.parse(" 640 X 480 ") == Resolution(640, 480)
    with pytest.raises(InputError, match=r"--resolution: '128' is not WIDTHxHEIGHT; fix: write e.g."):
        Resolution.parse("128")
    with pytest.raises(InputError, match="smaller than 8x8"):
        Resolution.parse("4x3")


def test_a_4_by_3_client_gets_exactly_the_resolution():
    assert fit_to_aspect(128 * 96, 4 / 3) == Resolution(128, 96)


@pytest.mark.parametrize("aspect", [16 / 9, 21 / 9, 1.0, 9 / 16, 0.3])
def test_any_aspect_keeps_the_pixel_budget(aspect):
    size = fit_to_aspect(128 * 96, aspect)
    assert size.width / size.height == pytest.approx(aspect, rel=0.03)
    assert size.pixels == pytest.approx(128 * 96, rel=0.03)


def test_degenerate_aspects_fall_back_to_4_by_3_and_sides_stay_visible():
    assert fit_to_aspect(128 * 96, float("nan")) == Resolution(128, 96)
    assert fit_to_aspect(128 * 96, 0.0) == Resolution(128, 96)
    tiny = fit_to_aspect(10, 50.0)
    assert tiny.width >= MIN_SIDE and tiny.height >= MIN_SIDE


def test_previews_are_at_most_a_quarter_and_fit_the_budget():
    full = 128 * 96
    assert preview_pixels(full, None, 0.15) == full // 4  # speed unknown yet
    assert preview_pixels(full, 1e9, 0.15) == full // 4  # fast: a quarter (the full image fits anyway)
    assert preview_pixels(full, 10_000, 0.15) == 1500  # 10k rays/s -> 1500 rays in 0.15 s
    assert preview_pixels(full, 10, 0.15) == MIN_SIDE * MIN_SIDE  # never below 8x8


def test_each_side_is_checked_and_the_doc_examples_hold():
    for text in ("4x96", "96x4", "7x7"):
        with pytest.raises(InputError, match="smaller than 8x8"):
            Resolution.parse(text)
    assert Resolution.parse("8x8") == Resolution(8, 8)
    # docs/viewer.md: a 16:9 window gets 148x83 for the 128x96 budget; a portrait 9:16 one 83x148
    assert fit_to_aspect(128 * 96, 16 / 9) == Resolution(148, 83)
    assert fit_to_aspect(128 * 96, 9 / 16) == Resolution(83, 148)  # 83 / (9 / 16) = 147.6: rounded, not cut
