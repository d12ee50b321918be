"""viser is an optional dependency of the project: import it with the exact install command as the fix."""

from __future__ import annotations

import importlib
import shlex
import sys
import warnings
from types import ModuleType

from stages.scene import InputError

VISER_VERSION = "1.1.1"
"""The version the viewer was written and tested against (pyproject.toml: optional dependency ``viewer``)."""


def install_command() -> str:
    """The pip command that installs the tested viser into the Python that is running now."""
    return f'{shlex.quote(sys.executable)} -m pip install "viser=={VISER_VERSION}"'


def require_viser() -> ModuleType:
    """``import viser``, or an InputError whose fix is the exact pip command."""
    try:
        viser = importlib.import_module("viser")
    except ImportError as exc:
        raise InputError("viser", f"the live viewer needs the optional package viser, which is not installed ({exc})",
                         f'{install_command()}   (or, in the project folder: pip install -e ".[viewer]")') from exc
    found = getattr(viser, "__version__", "unknown")
    if found != VISER_VERSION:
        # the GUI calls and the client protocol the tests read are those of the tested version
        warnings.warn(f"livescene view was tested with viser {VISER_VERSION}, this is {found}; "
                      f"if the viewer misbehaves: {install_command()}", stacklevel=2)
    return viser
