"""Synthetic captures of interactive rooms, rendered with open3d ray casting, with their ground truth."""

from .generate import generate_capture
from .renderer import SceneRenderer, TruthRenderer
from .spec import CaptureSpec, CaptureSpecError, load_spec, spec_from_dict, spec_to_dict

__all__ = [
    "CaptureSpec",
    "CaptureSpecError",
    "SceneRenderer",
    "TruthRenderer",
    "generate_capture",
    "load_spec",
    "spec_from_dict",
    "spec_to_dict",
]
