"""A check shared by the config and capture-spec tests: a loaded dataclass tree holds every YAML value as written."""

from __future__ import annotations

from typing import Any


def assert_unchanged(raw: Any, loaded: Any, where: str) -> None:
    """Every value the YAML gives is in ``loaded`` (a dict of the dataclass tree) as written; an int in a float
    field may come back as that float."""
    if isinstance(raw, dict):
        for key, value in raw.items():
            assert_unchanged(value, loaded[key], f"{where}.{key}")
    elif isinstance(raw, list):
        assert isinstance(loaded, list) and len(loaded) == len(raw), where
        for i, (a, b) in enumerate(zip(raw, loaded, strict=True)):
            assert_unchanged(a, b, f"{where}[{i}]")
    else:
        assert loaded == raw and (type(loaded) is type(raw) or type(loaded) is float), (where, raw, loaded)
