"""The truth files of a capture hold the spec's values in output units (docs/captures.md, "Output layout")."""

from __future__ import annotations

import csv
import json
from types import SimpleNamespace

import numpy as np
import pytest
import yaml
from tiny_capture_spec import small_spec

from stages.capture import generate_capture, spec_from_dict
from stages.capture.generate import frame_gains, key_frame_values, scene_info
from stages.capture.geometry import build_scene


@pytest.fixture(scope="module")
def mm_capture(tmp_path_factory):
    spec = small_spec(n_frames=2, width=32, height=24)
    spec.units.name, spec.units.per_metre = "mm", 1000.0
    return generate_capture(spec, tmp_path_factory.mktemp("mm") / "cap", progress=False)


def test_scene_json_is_in_output_units(mm_capture):
    info = json.loads((mm_capture / "truth" / "scene.json").read_text())
    assert info["units"] == "mm" and info["units_per_metre"] == 1000.0
    np.testing.assert_allclose(info["scene_box"], [[-2000, -1800, 0], [2000, 1800, 2500]])  # room [4, 3.6, 2.5] m
    assert info["lights"] == [{"position": pytest.approx([300, 200, 2350]), "intensity": 0.6}]
    cabinet, drawer = info["objects"]
    # cabinet: 0.6 x 0.5 x 0.9 at (-0.45, 1.5, 0), door 2 cm thick hinged on the left at (-0.45 - 0.3, 1.5 - 0.27)
    assert (cabinet["kind"], cabinet["joint"], cabinet["limits_unit"]) == ("door", "revolute", "rad")
    np.testing.assert_allclose(cabinet["axis_world"], [0, 0, -1])
    np.testing.assert_allclose(cabinet["pivot_world"], [-750, 1230, 0], atol=1e-9)
    np.testing.assert_allclose(cabinet["limits"], [0, np.deg2rad(100)])
    assert (drawer["joint"], drawer["limits_unit"]) == ("prismatic", "mm")
    np.testing.assert_allclose(drawer["axis_world"], [0, -1, 0])
    np.testing.assert_allclose(drawer["limits"], [0, 300])


def test_transforms_and_states_csv_hold_each_frames_time_and_states(mm_capture):
    truth = json.loads((mm_capture / "truth" / "transforms.json").read_text())
    assert truth["fl_x"] == pytest.approx(16 / np.tan(np.deg2rad(35)))  # 32 px wide, fov 70 degrees
    assert (truth["w"], truth["h"], truth["cx"], truth["cy"]) == (32, 24, 16, 12)
    assert [f["time_s"] for f in truth["frames"]] == [0.0, 0.1]  # 10 fps
    # two frames: t = 0 (all closed) and t = 1 (the cabinet closed again at 0.85, the drawer open from 0.7)
    assert [f["state"] for f in truth["frames"]] == [{"cabinet": 0.0, "drawer": 0.0}, {"cabinet": 0.0, "drawer": 1.0}]
    with (mm_capture / "truth" / "states.csv").open() as fh:
        rows = list(csv.reader(fh))
    assert rows == [
        ["frame", "source_index", "object", "value"],
        ["frame_00000.png", "0", "cabinet", "0.0"],
        ["frame_00000.png", "0", "drawer", "0.0"],
        ["frame_00001.png", "1", "cabinet", "0.0"],
        ["frame_00001.png", "1", "drawer", "1.0"],
    ]
    prompts = yaml.safe_load((mm_capture / "prompts.yaml").read_text())
    assert prompts["cabinet"] == {
        "synonyms": ["cupboard"],
        "description": "a low cabinet with one door hinged on the left",
    }
    assert yaml.safe_load((mm_capture / "mapping.yaml").read_text()) == {1: "cabinet", 2: "drawer"}


def test_scene_json_turns_joints_with_the_objects_yaw():
    spec = spec_from_dict(
        {
            "name": "y",
            "objects": [
                {"name": "chest", "kind": "lid", "position": [1.0, 0.5, 0.2], "size": [0.8, 0.4, 0.5], "yaw_deg": 90}
            ],
        }
    )
    (chest,) = scene_info(spec, SimpleNamespace(model=build_scene(spec)))["objects"]
    # lid hinge: axis -x through (0, depth/2, height) of the object; turned 90 degrees: -y through (-0.2, 0, 0.5)
    np.testing.assert_allclose(chest["axis_world"], [0, -1, 0], atol=1e-12)
    np.testing.assert_allclose(chest["pivot_world"], [0.8, 0.5, 0.7], atol=1e-12)
    np.testing.assert_allclose(chest["limits"], [0, np.deg2rad(80)])


def _keys_spec(**key_frames):
    return spec_from_dict(
        {
            "name": "k",
            "key_frames": key_frames,
            "objects": [{"name": "box", "kind": "drawer", "position": [0, 0, 0], "size": [0.5, 0.5, 0.5]}],
        }
    )


def test_key_frames_every_nth_frame_and_the_last():
    states = np.linspace(0, 1, 12)[:, None]
    assert list(key_frame_values(_keys_spec(every=5, include_last=False), states)) == [
        "frame_00000",
        "frame_00005",
        "frame_00010",
    ]
    assert list(key_frame_values(_keys_spec(every=5), states)) == [
        "frame_00000",
        "frame_00005",
        "frame_00010",
        "frame_00011",
    ]
    assert list(key_frame_values(_keys_spec(every=5, include_last=False), states[:11])) == [
        "frame_00000",
        "frame_00005",
        "frame_00010",
    ]


def test_key_frame_values_are_rounded_like_typed_numbers():
    got = key_frame_values(_keys_spec(every=1, decimals=2), np.array([[0.12345], [0.987]]))
    assert got == {"frame_00000": {"box": 0.12}, "frame_00001": {"box": 0.99}}


def test_key_frame_noise_has_its_deviation_and_stays_in_range():
    n = 400
    half = key_frame_values(_keys_spec(every=1, noise_std=0.05, decimals=6), np.full((n, 1), 0.5))
    deviation = np.array([v["box"] for v in half.values()]) - 0.5
    assert 0.04 < deviation.std() < 0.06
    opened = key_frame_values(_keys_spec(every=1, noise_std=0.05, decimals=6), np.ones((n, 1)))
    values = np.array([v["box"] for v in opened.values()])
    assert values.max() == 1.0 and (values < 1.0).mean() > 0.3  # clipped to [0, 1], not shifted


def test_frame_gains_split_exposure_and_white_balance():
    def spec(exposure, white_balance):
        return spec_from_dict(
            {
                "name": "g",
                "video": {"n_frames": 400, "exposure_jitter": exposure, "white_balance_jitter": white_balance},
            }
        )

    assert frame_gains(spec(0.0, 0.0)) is None
    exposure = np.log(frame_gains(spec(0.05, 0.0)))
    np.testing.assert_allclose(exposure, exposure[:, :1].repeat(3, axis=1))  # the same gain on every channel
    assert 0.04 < exposure[:, 0].std() < 0.06
    balance = np.log(frame_gains(spec(0.0, 0.05)))
    assert all(0.04 < balance[:, c].std() < 0.06 for c in range(3))
    assert np.abs(np.corrcoef(balance.T) - np.eye(3)).max() < 0.2  # channels drawn apart
