"""Object masks from LiveScene npy, PNG id maps, COCO JSON or LabelMe JSON, as canonical LiveScene masks."""

from .coco_rle import decode_rle, encode_counts_string, encode_rle
from .errors import LabelError
from .ingest import UNRELIABLE_DIVISOR, LabelsConfig, detect_format, ingest_labels, open_label_set
from .name_table import NameTable, read_name_table
from .resize import resize_labels

__all__ = [
    "UNRELIABLE_DIVISOR",
    "LabelError",
    "LabelsConfig",
    "NameTable",
    "decode_rle",
    "detect_format",
    "encode_counts_string",
    "encode_rle",
    "ingest_labels",
    "open_label_set",
    "read_name_table",
    "resize_labels",
]
