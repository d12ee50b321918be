"""Methods by name: each builds a model (a ``LiveSceneModel`` or a subclass) that the shared trainer trains.

A baseline registers itself with ``register_method("mk-planes", MKPlanesModel)``;
its class takes ``(ModelConfig, SceneInfo)`` and overrides the field hooks.
"""

from __future__ import annotations

from collections.abc import Callable

from torch import nn

from ..config import ModelConfig
from .livescene import LiveSceneModel, SceneInfo

MethodBuilder = Callable[[ModelConfig, SceneInfo], nn.Module]

METHODS: dict[str, MethodBuilder] = {"livescene": LiveSceneModel}


def register_method(name: str, builder: MethodBuilder) -> None:
    """Make ``name`` trainable with ``livescene train --method name``."""
    METHODS[name] = builder


def build_model(name: str, config: ModelConfig, info: SceneInfo) -> nn.Module:
    _load_baselines()
    if name not in METHODS:
        raise KeyError(f"unknown method {name!r}; registered: {sorted(METHODS)}")
    return METHODS[name](config, info)


def _load_baselines() -> None:
    """Import the baselines module, so its register_method calls run (on use: they import this module)."""
    from . import baselines  # noqa: F401


__all__ = ["METHODS", "LiveSceneModel", "SceneInfo", "build_model", "register_method"]
