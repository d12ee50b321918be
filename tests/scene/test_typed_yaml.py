"""The strict dataclass-from-YAML loader: types from the hints, unknown keys, key paths and fixes in errors."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import pytest
import yaml

from stages.scene import InputError
from stages.scene.typed_yaml import from_mapping


@dataclass
class Inner:
    size: int = 4
    ratio: float = 0.5
    tags: list[str] = field(default_factory=list)


@dataclass
class Item:
    name: str
    weight: float = 1.0


@dataclass
class Outer:
    count: int = 1
    scale: float = 1.0
    flag: bool = False
    label: str = "a"
    mode: Literal["fast", "slow", "off"] = "fast"
    sizes: list[int] = field(default_factory=lambda: [1, 2])
    grid: list[list[int]] = field(default_factory=lambda: [[1, 2]])
    pair: tuple[int, str] = (0, "x")
    many: tuple[float, ...] = ()
    colour: list[float] | None = None
    hinge: str | None = None
    names: dict[str, int] = field(default_factory=dict)
    inner: Inner = field(default_factory=Inner)
    items: list[Item] = field(default_factory=list)


class SpecError(InputError):
    """An InputError subclass, as the stages define them."""


def load(data: object, **kwargs) -> Outer:
    return from_mapping(Outer, data, path="file.yaml", **kwargs)


def refusal(data: object, **kwargs) -> str:
    with pytest.raises(InputError) as info:
        load(data, **kwargs)
    return str(info.value)


def test_values_of_the_right_type_load_and_defaults_fill_the_rest():
    text = """
count: 3
scale: 2            # an int where a float is meant is that float
flag: true
label: hello
mode: slow
sizes: [4, 5]
grid: [[1, 2], [3, 4]]
pair: [7, seven]
many: [1, 2.5]
colour: [1, 0.5, 0]
names: {a: 1}
inner: {size: 8, tags: [x]}
items: [{name: door}, {name: lid, weight: 2}]
"""
    cfg = load(yaml.safe_load(text))
    assert cfg == Outer(count=3, scale=2.0, flag=True, label="hello", mode="slow", sizes=[4, 5], grid=[[1, 2], [3, 4]],
                        pair=(7, "seven"), many=(1.0, 2.5), colour=[1.0, 0.5, 0.0], names={"a": 1},
                        inner=Inner(size=8, tags=["x"]), items=[Item("door"), Item("lid", 2.0)])
    assert type(cfg.scale) is float and all(type(v) is float for v in cfg.colour)
    assert load({}) == Outer() and load({"colour": None}).colour is None


def test_exponent_floats_that_pyyaml_reads_as_strings_are_numbers():
    assert yaml.safe_load("x: 1e-3")["x"] == "1e-3"  # YAML 1.1: no dot, so a string
    assert load(yaml.safe_load("scale: 1e-3")).scale == pytest.approx(1e-3)
    assert load({"many": ["2E+4", -1]}).many == (2e4, -1.0)
    assert "without quotes" in refusal({"scale": "0.5"})  # a quoted plain number is still refused


@pytest.mark.parametrize(("data", "words"), [
    ({"count": "7"}, ["count is '7' (a string)", "expected an integer", "without quotes"]),
    ({"count": 7.0}, ["count is 7.0", "expected an integer", "write count as an integer: 7"]),
    ({"count": True}, ["count is True (a boolean)", "expected an integer"]),
    ({"scale": "fast"}, ["scale is 'fast'", "expected a number"]),
    ({"flag": 1}, ["flag is 1 (an integer)", "expected true or false", "e.g. false"]),
    ({"flag": "yes"}, ["flag is 'yes' (a string)", "expected true or false", "without quotes"]),
    ({"label": 7}, ["label is 7 (an integer)", "expected a string", "in quotes: '7'"]),
    ({"mode": 7}, ["mode is 7", "expected one of 'fast', 'slow', 'off'", "e.g. fast"]),
    ({"mode": False}, ["mode is False (a boolean)", "quote the word", "mode: 'off'", "--set \"mode='off'\""]),
    ({"label": None}, ["label is None (null)", "expected a string"]),
    ({"sizes": ["a", 3]}, ["sizes[0] is 'a'", "expected an integer", "write sizes as a list of integers, e.g. [1, 2]"]),
    ({"sizes": 3}, ["sizes is 3", "expected a list of integers"]),
    ({"grid": [[1, "b"]]}, ["grid[0][1] is 'b'", "a list of lists of integers, e.g. [[1, 2]]"]),
    ({"pair": [1, 2, 3]}, ["pair is [1, 2, 3]", "a list of 2 items (an integer, a string)"]),
    ({"colour": "red"}, ["colour is 'red'", "expected a list of numbers or null"]),
    ({"hinge": 3}, ["hinge is 3", "expected a string or null"]),
    ({"names": {"a": "1"}}, ["names.a is '1'", "expected an integer"]),
    ({"inner": {"size": "big"}}, ["inner.size is 'big'", "expected an integer", "e.g. 4"]),
    ({"inner": [1]}, ["inner is [1] (a list)", "expected a mapping of Inner fields", "ratio"]),
    ({"items": [{"name": "a", "weight": "x"}]}, ["items[0].weight is 'x'", "expected a number"]),
    ({"items": [{"name": 5}]}, ["items[0].name is 5", "expected a string"]),
])
def test_wrong_types_name_the_file_key_value_type_and_fix(data, words):
    message = refusal(data)
    assert message.startswith("file.yaml: ") and "; fix: " in message
    for word in words:
        assert word in message, (word, message)


def test_unknown_keys_name_the_key_path_and_the_valid_keys():
    message = refusal({"inner": {"sise": 3}})
    assert "inner has unknown keys ['sise']" in message
    assert "use only ['ratio', 'size', 'tags']" in message
    assert "the top level has unknown keys ['cuont']" in refusal({"cuont": 1})
    assert "spec.inner has unknown keys" in refusal({"inner": {"x": 1}}, root="spec")
    assert "items[1] has unknown keys ['colour']" in refusal({"items": [{"name": "a"}, {"name": "b", "colour": 1}]})


def test_required_keys_and_the_top_level_shape():
    assert "items[0] is missing required keys ['name']" in refusal({"items": [{"weight": 1}]})
    assert "the top level is [1] (a list), expected a mapping of Outer fields" in refusal([1])


def test_the_callers_error_type_and_path_are_used():
    with pytest.raises(SpecError) as info:
        from_mapping(Outer, {"count": "x"}, path=Path("dir") / "spec.yaml", root="spec", error=SpecError)
    assert info.value.path == Path("dir/spec.yaml") and "spec.count" in info.value.problem
    assert info.value.fix.startswith("write spec.count as an integer")


def test_a_type_the_loader_cannot_check_is_a_programming_error():
    @dataclass
    class Odd:
        where: Path = Path(".")

    with pytest.raises(TypeError, match="cannot check"):
        from_mapping(Odd, {"where": "x"}, path="f")
    assert dataclasses.asdict(from_mapping(Odd, {}, path="f")) == {"where": Path(".")}
