"""The export stage: meshes and point clouds of a trained run at chosen object states (docs/export.md)."""

from .exporter import ExportOptions, export_run, export_state, training_views
from .mesh_io import FORMATS, read_glb, write_geometry
from .state_spec import parse_state_string, state_slug

__all__ = [
    "FORMATS",
    "ExportOptions",
    "export_run",
    "export_state",
    "parse_state_string",
    "read_glb",
    "state_slug",
    "training_views",
    "write_geometry",
]
