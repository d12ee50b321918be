"""Method names are listed once per layer: the model stage's registry, the config schema (which the workflow
reads), and the scene sheet's `methods` pattern; this holds the three equal."""

from __future__ import annotations

import re
from pathlib import Path

import yaml

from stages.compare.method_comparison import ALL_METHODS
from stages.model.methods import METHODS

SCHEMAS = Path(__file__).resolve().parents[2] / "workflow" / "schemas"


def test_schemas_list_the_registered_methods():
    config = yaml.safe_load((SCHEMAS / "config.schema.yaml").read_text())
    enum = config["properties"]["methods"]["items"]["enum"]
    assert sorted(enum) == sorted(METHODS) == sorted(ALL_METHODS)
    props = config["properties"]  # the report's sweeps and the export name methods too: a typo is refused
    for section, key in (("report", "sweep_methods"), ("export", "methods")):
        assert props[section]["properties"][key]["items"]["enum"] == enum, (section, key)
    pattern = yaml.safe_load((SCHEMAS / "scenes.schema.yaml").read_text())["properties"]["methods"]["pattern"]
    for name in enum:
        assert re.fullmatch(pattern, name) and re.fullmatch(pattern, f"livescene,{name}"), name
    assert not re.fullmatch(pattern, "nerf") and not re.fullmatch(pattern, "livescene,nerf")
    named = set(re.findall(r"[a-z][a-z-]*[a-z]", pattern))
    assert named == set(enum), "the scene sheet's pattern names other methods than the config schema"
