"""Language: text encoders, language-table targets, commands that set object states, grounding maps.

Heavy libraries (sentence-transformers, open_clip) load only when an encoder
is built, so importing this package and parsing commands by name stay fast.
"""

from .commands import Action, CommandParser, CommandResult, parse_command, split_clauses
from .embedding_cache import EmbeddingCache, default_cache_dir
from .encoder import (
    DEFAULT_ENCODER,
    CachedEncoder,
    EncoderError,
    SentenceTransformerEncoder,
    TextEncoder,
    load_encoder,
    normalize_rows,
)
from .grounding import DEFAULT_THRESHOLD, Grounder
from .object_resolution import (
    AmbiguousObjectError,
    CommandError,
    ObjectResolver,
    Resolution,
    ResolverConfig,
    UnknownObjectError,
)
from .openclip_encoder import OpenClipEncoder, masked_object_crop
from .relevancy import CANONICAL_NEGATIVES, TEMPERATURE, lerf_relevancy, softmax
from .targets import LanguageTargets, build_crop_targets, build_targets
from .vocabulary import ObjectEntry, ObjectVocabulary, normalize_phrase

__all__ = [
    "CANONICAL_NEGATIVES",
    "DEFAULT_ENCODER",
    "DEFAULT_THRESHOLD",
    "TEMPERATURE",
    "Action",
    "AmbiguousObjectError",
    "CachedEncoder",
    "CommandError",
    "CommandParser",
    "CommandResult",
    "EmbeddingCache",
    "EncoderError",
    "Grounder",
    "LanguageTargets",
    "ObjectEntry",
    "ObjectResolver",
    "ObjectVocabulary",
    "OpenClipEncoder",
    "Resolution",
    "ResolverConfig",
    "SentenceTransformerEncoder",
    "TextEncoder",
    "UnknownObjectError",
    "build_crop_targets",
    "build_targets",
    "default_cache_dir",
    "lerf_relevancy",
    "load_encoder",
    "masked_object_crop",
    "normalize_phrase",
    "normalize_rows",
    "parse_command",
    "softmax",
    "split_clauses",
]
