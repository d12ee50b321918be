"""Key-frame interaction variables (LiveScene, CoNeRF or CSV) interpolated to every extracted frame."""

from .annotations import Annotations, KeyValue, read_annotations
from .errors import StateError
from .frame_table import FrameTable, read_frame_table
from .interpolation import METHODS, interpolate, leave_one_out
from .pipeline import StatesConfig, compute_states, read_states_csv

__all__ = [
    "METHODS",
    "Annotations",
    "FrameTable",
    "KeyValue",
    "StateError",
    "StatesConfig",
    "compute_states",
    "interpolate",
    "leave_one_out",
    "read_annotations",
    "read_frame_table",
    "read_states_csv",
]
