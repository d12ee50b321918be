"""Capture specs are typed: every shipped spec loads unchanged, wrong types are refused with the key path."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml
from yaml_round_trip import assert_unchanged

from stages.capture import CaptureSpecError, load_spec, spec_from_dict, spec_to_dict
from stages.capture.spec import CaptureSpec, LightSpec, ObjectSpec, ScheduleSpec
from stages.stability.checks.tiny_scenes import capture_spec_data

PRESETS = Path(__file__).resolve().parents[2] / "config" / "captures"
SHIPPED = sorted(p.stem for p in PRESETS.glob("*.yaml"))


@pytest.mark.parametrize("preset", SHIPPED)
def test_every_shipped_spec_loads_unchanged_and_round_trips(preset):
    raw = yaml.safe_load((PRESETS / f"{preset}.yaml").read_text())
    spec = load_spec(PRESETS / f"{preset}.yaml")
    data = spec_to_dict(spec)
    assert_unchanged(raw, data, preset)
    assert isinstance(spec.objects[0], ObjectSpec) and isinstance(spec.objects[0].schedule, ScheduleSpec)
    assert all(isinstance(light, LightSpec) for light in spec.render.lights)
    assert spec_from_dict(data, f"{preset}.yaml") == spec
    assert spec_from_dict(yaml.safe_load(yaml.safe_dump(data)), f"{preset}.yaml") == spec  # truth/spec.yaml


def test_the_specs_the_tests_and_the_stability_suite_use_load(small_spec):
    spec = small_spec(n_frames=3, width=40, height=30)  # what test_capture_cli writes as its spec file
    assert spec_from_dict(yaml.safe_load(yaml.safe_dump(spec_to_dict(spec))), "small.yaml") == spec
    data = capture_spec_data(PRESETS, "tiny", width=32, height=24, n_frames=6)  # the stability suite's tiny captures
    spec = spec_from_dict(data, PRESETS / "tiny.yaml")
    assert (spec.video.width, spec.video.n_frames, spec.render.shadows) == (32, 6, False)
    assert spec_from_dict({"name": "bare"}) == CaptureSpec(name="bare")


def _inside(data: dict, what: str, i: int, **fields) -> None:
    data[what][i].update(fields)


@pytest.mark.parametrize(("edit", "words"), [
    (lambda d: d["objects"][0].update(limits=[0, "x"]),
     ["spec.objects[0].limits[1] is 'x' (a string), expected a number"]),
    (lambda d: d["video"].update(fps="10"), ["spec.video.fps is '10' (a string)", "without quotes"]),
    (lambda d: d["video"].update(n_frames=12.5), ["spec.video.n_frames is 12.5", "expected an integer"]),
    (lambda d: d["render"]["lights"][0].update(shadows="yes"), ["spec.render.lights[0].shadows is 'yes'"]),
    (lambda d: d["objects"][0].pop("kind"), ["spec.objects[0] is missing required keys ['kind']"]),
    (lambda d: d["objects"][1]["schedule"].update(speed=1), ["spec.objects[1].schedule has unknown keys ['speed']",
                                                            "use only ['interpolation', 'keys']"]),
    (lambda d: d.update(name=2024), ["spec.name is 2024 (an integer), expected a string", "in quotes: '2024'"]),
    (lambda d: d.update(objects={"cabinet": {}}), ["spec.objects is", "expected a list of mappings of ObjectSpec"]),
    (lambda d: d["objects"][0].update(position=[0.0, float("nan"), 0.0]), [".position is [0.0, nan, 0.0], expected 3"]),
    (lambda d: _inside(d, "objects", 0, position=[9.0, 0.0, 0.0]),
     ["objects[0] (cabinet)", "outside the room", "move it inside the room"]),
    (lambda d: _inside(d, "objects", 0, position=[0.0, 0.0, -0.3]), ["objects[0]", "outside the room"]),
    (lambda d: _inside(d, "objects", 0, size=[0.4, 0.4, 9.0]), ["objects[0]", "outside the room"]),
    (lambda d: d["furniture"].append({"name": "sofa", "position": [0.0, 0.0, 0.0], "size": [40.0, 1.0, 1.0]}),
     ["furniture[", "(sofa)", "outside the room"]),
])
def test_wrong_types_name_the_file_and_the_key(tmp_path, edit, words):
    data = yaml.safe_load((PRESETS / "tiny.yaml").read_text())
    edit(data)
    path = tmp_path / "broken.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(CaptureSpecError) as info:
        load_spec(path)
    message = str(info.value)
    assert message.startswith(f"{path}: ") and "; fix: " in message
    for word in words:
        assert word in message, (word, message)


def test_a_yawed_object_flush_against_a_wall_is_inside():
    data = yaml.safe_load((PRESETS / "tiny.yaml").read_text())
    half_x = data["room"][0] / 2
    # 0.4 wide, 0.2 deep, turned 90 degrees: 0.1 of it reaches along x, so its centre may sit 0.1 from the wall
    data["objects"][0].update(position=[half_x - 0.1, 0.0, 0.0], size=[0.4, 0.2, 0.5], yaw_deg=90.0)
    assert load_spec_data(data).objects[0].yaw_deg == 90.0
    data["objects"][0]["position"][0] += 0.01
    with pytest.raises(CaptureSpecError, match="outside the room"):
        load_spec_data(data)


def load_spec_data(data: dict) -> CaptureSpec:
    return spec_from_dict(data, "inside.yaml")
