"""Synthetic captures of interactive rooms, rendered with open3d ray casting, with their ground truth."""

from .generate import generate_capture
from .renderer import SceneRenderer, TruthRenderer
from .spec import CaptureSpec, CaptureSpecError, load_spec, spec_from_dict, spec_to_dict
from .truth_dataset import CaptureFolderError, capture_to_dataset

__all__ = [
    "CaptureFolderError",
    "CaptureSpec",
    "CaptureSpecError",
    "SceneRenderer",
    "TruthRenderer",
    "capture_to_dataset",
    "generate_capture",
    "load_spec",
    "spec_from_dict",
    "spec_to_dict",
]
