"""The model stage: LiveScene in plain PyTorch, its trainer, presets, and the render/control API.

Imports only torch, numpy, yaml and stages.scene, so it runs on a GPU machine
without pycolmap, open3d or Snakemake.
"""

from .config import RunConfig, load_config
from .methods import METHODS, LiveSceneModel, SceneInfo, build_model, register_method
from .run import LoadedRun, load_run
from .trainer import Trainer, TrainingDiverged

__all__ = [
    "METHODS",
    "LiveSceneModel",
    "LoadedRun",
    "RunConfig",
    "SceneInfo",
    "Trainer",
    "TrainingDiverged",
    "build_model",
    "load_config",
    "load_run",
    "register_method",
]
