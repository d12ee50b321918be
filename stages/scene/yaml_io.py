"""Reading the small YAML files every stage takes (mappings, key frames, prompts, specs, presets)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from .errors import InputError, SceneError


def read_yaml_mapping(
    path: str | Path,
    shape: str,
    *,
    error: type[InputError] = SceneError,
    missing_ok: bool = False,
) -> dict[Any, Any]:
    """Parse ``path`` as a YAML mapping; ``shape`` tells the user what the file should hold.

    Errors name the file and the fix. A missing file returns ``{}`` when ``missing_ok``,
    an empty file always does (an empty annotation file is a valid "nothing yet").
    """
    path = Path(path)
    if not path.is_file():
        if missing_ok:
            return {}
        raise error(path, "file not found", f"check the path; the file should hold {shape}")
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise error(path, f"not valid YAML ({exc})", "repair the file") from exc
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise error(path, "top level is not a mapping", f"write {shape}")
    return data
