"""Articulated objects move the way docs/captures.md describes: outwards, about the named edge, by the limits."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from stages.capture import load_spec, spec_from_dict
from stages.capture.geometry import build_scene

PRESETS = Path(__file__).resolve().parents[2] / "config" / "captures"
W, D, H, T = 0.6, 0.5, 0.9, 0.02  # carcass width, depth, height, panel thickness
X0, Y0 = 0.0, 1.0  # footprint centre of the object (front faces -y)
Y_OUT = Y0 - D / 2 - T  # the outer face of a closed door


def _model(**obj):
    spec = spec_from_dict(
        {"name": "g", "objects": [{"name": "box", "position": [X0, Y0, 0.0], "size": [W, D, H], "thickness": T, **obj}]}
    )
    return build_scene(spec)


def _centre(model, part: str, state: float) -> np.ndarray:
    index = [p.name for p in model.parts].index(f"box/{part}")
    return model.part_poses(np.array([state]))[index][:3, 3]


@pytest.mark.parametrize(
    ("hinge", "open_90"),
    [
        # door centre when open 90 degrees: it stands out of the front, turned about its hinge edge
        ("left", [X0 - W / 2 + T / 2, Y_OUT - W / 2, H / 2]),
        ("right", [X0 + W / 2 - T / 2, Y_OUT - W / 2, H / 2]),
        ("bottom", [X0, Y_OUT - H / 2, T / 2]),  # a flap lying forward at the floor
        ("top", [X0, Y_OUT - H / 2, H - T / 2]),  # a flap raised to the top
        (None, [X0 - W / 2 + T / 2, Y_OUT - W / 2, H / 2]),  # the first hinge: left
    ],
)
def test_a_door_swings_outwards_about_its_hinge(hinge, open_90):
    model = _model(kind="door", hinge=hinge, limits=[0, 90])
    np.testing.assert_allclose(_centre(model, "door", 0.0), [X0, Y0 - D / 2 - T / 2, H / 2], atol=1e-12)
    np.testing.assert_allclose(_centre(model, "door", 1.0), open_90, atol=1e-12)


def test_a_door_half_open_is_at_half_its_limit():
    model = _model(kind="door", hinge="left", limits=[0, 90])
    # the door centre is (W/2, T/2) from the hinge line when closed; at state 0.5 that turns 45 degrees outwards
    r = np.hypot(W / 2, T / 2)
    angle = np.arctan2(T / 2, W / 2) - np.pi / 4
    expected = [X0 - W / 2 + r * np.cos(angle), Y_OUT + r * np.sin(angle), H / 2]
    np.testing.assert_allclose(_centre(model, "door", 0.5), expected, atol=1e-12)


def test_a_lid_opens_upwards_about_its_back_edge():
    model = _model(kind="lid", limits=[0, 90])
    np.testing.assert_allclose(_centre(model, "lid", 0.0), [X0, Y0, H + T / 2], atol=1e-12)
    np.testing.assert_allclose(_centre(model, "lid", 1.0), [X0, Y0 + D / 2 + T / 2, H + D / 2], atol=1e-12)


def test_a_drawer_slides_out_of_the_front_by_its_limit():
    model = _model(kind="drawer", limits=[0.0, 0.3])
    closed = [X0, Y0 - D / 2 - T / 2, H / 2]
    np.testing.assert_allclose(_centre(model, "front", 0.0), closed, atol=1e-12)
    np.testing.assert_allclose(_centre(model, "front", 1.0), [X0, closed[1] - 0.3, H / 2], atol=1e-12)


@pytest.mark.parametrize(
    ("kind", "limits"),
    [("door", (0.0, np.deg2rad(100.0))), ("lid", (0.0, np.deg2rad(80.0))), ("drawer", (0.0, 0.75 * D))],
)
def test_kind_default_limits(kind, limits):
    np.testing.assert_allclose(_model(kind=kind).joints[0].limits, limits)


def test_furniture_stands_on_its_position():
    spec = spec_from_dict(
        {"name": "g", "furniture": [{"name": "table", "position": [0.5, -0.5, 0.1], "size": [0.8, 0.6, 0.7]}]}
    )
    model = build_scene(spec)
    table = next(p for p in model.parts if p.name == "furniture/table")
    low = table.rest[:3, 3] - table.half
    high = table.rest[:3, 3] + table.half
    np.testing.assert_allclose(low, [0.1, -0.8, 0.1], atol=1e-12)
    np.testing.assert_allclose(high, [0.9, -0.2, 0.8], atol=1e-12)


@pytest.mark.parametrize(
    ("preset", "name", "facing"),
    [
        ("loft", "side drawer", [1.0, 0.0]),  # its comment: "front faces sideways (+x, yaw 90)"
        ("loft", "tall cupboard", [-1.0, 0.0]),  # on the right (+x) wall, facing into the room
        ("office", "supply cupboard", [1.0, 0.0]),  # on the left (-x) wall, facing into the room
    ],
)
def test_yaw_turns_the_front_as_the_presets_expect(preset, name, facing):
    spec = load_spec(PRESETS / f"{preset}.yaml")
    k = spec.object_names.index(name)
    part = {"door": "door", "drawer": "front", "lid": "lid"}[spec.objects[k].kind]
    model = build_scene(spec)
    index = [p.name for p in model.parts].index(f"{name}/{part}")
    centre = model.part_poses(np.zeros(len(spec.objects)))[index][:3, 3]
    direction = centre[:2] - np.asarray(spec.objects[k].position[:2])
    np.testing.assert_allclose(direction / np.linalg.norm(direction), facing, atol=1e-9)
