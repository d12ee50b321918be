"""Strict dataclass trees from parsed YAML, checked against the dataclasses' type hints.

Model presets, method overlays, ``--set`` overrides and capture specs are plain mappings once YAML has
parsed them; ``from_mapping`` turns one into nested dataclasses. It converts nothing a person did not
mean: a quoted ``'7'`` stays a string and is refused where a number is meant, ``1`` is not ``true``,
and ``7`` is not ``'7'``. Every refusal is an ``InputError`` (file / problem / fix) naming the key
path, the value, the expected type and what to write instead.

Two conversions are made because they are what the YAML says, not a guess:

- an integer where a float is meant becomes that float (``fps: 10``);
- a string in exponent notation where a float is meant becomes that float: PyYAML follows YAML 1.1,
  which reads ``1e-3`` (no dot) as a string although every reader of the file means a number.

Supported type hints: ``int``, ``float``, ``bool``, ``str``, ``Literal[...]``, ``list[T]``,
``tuple[T, ...]`` / ``tuple[A, B]``, ``dict[K, V]``, nested dataclasses, ``Optional`` and other unions,
``Any``. Anything else is a programming error (``TypeError``), raised when the field is first checked.
"""

from __future__ import annotations

import dataclasses
import functools
import numbers
import re
import types
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Literal, TypeVar, Union

import yaml

from .errors import InputError

T = TypeVar("T")

# what PyYAML's YAML 1.1 resolver leaves a string but YAML 1.2 (and a person) reads as a float
_EXPONENT_FLOAT = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)[eE][-+]?\d+")
# unquoted scalars YAML 1.1 reads as booleans: a string field given one of these needs quotes
_YAML_BOOL_WORDS = "yes/no/on/off/true/false"


class _Refused(Exception):
    """A value the type hint does not allow; turned into the caller's InputError with the file named."""

    def __init__(self, where: str, value: Any, expected: str, fix: str) -> None:
        super().__init__(where)
        self.where, self.value, self.expected, self.fix = where, value, expected, fix


def from_mapping(
    cls: type[T],
    data: Any,
    *,
    path: str | Path,
    root: str = "",
    error: type[InputError] = InputError,
) -> T:
    """Build dataclass ``cls`` (and the dataclasses inside it) from ``data``, refusing what its hints do not allow.

    ``path`` is the file (or option, e.g. ``--set``) the mapping came from and is what the error names;
    ``root`` prefixes every key path in messages (``spec`` -> ``spec.camera.radius``); ``error`` is the
    ``InputError`` subclass raised. Fields left out keep their defaults; a required field left out, an
    unknown key and a value of the wrong type are errors.
    """
    try:
        return _build(cls, data, root, path, error)
    except _Refused as r:
        raise error(path, f"{_label(r.where)} is {_show(r.value)}, expected {r.expected}", r.fix) from None


def _build(cls: type[T], data: Any, where: str, path: str | Path, error: type[InputError]) -> T:
    fields = _fields(cls)
    if not isinstance(data, Mapping):
        raise _Refused(where, data, f"a mapping of {cls.__name__} fields",
                       f"write {_label(where)} as key: value pairs, keys from {sorted(fields)}")
    unknown = sorted(str(k) for k in data if k not in fields)
    if unknown:
        raise error(path, f"{_label(where)} has unknown keys {unknown}", f"use only {sorted(fields)}")
    missing = [name for name, f in fields.items() if _required(f) and name not in data]
    if missing:
        raise error(path, f"{_label(where)} is missing required keys {missing}",
                    f"add {', '.join(missing)} to {_label(where)}")
    hints = _hints(cls)
    kwargs = {key: _convert(hints[key], value, _join(where, key), fields[key], path, error)
              for key, value in data.items()}
    return cls(**kwargs)


def _convert(tp: Any, value: Any, where: str, field: dataclasses.Field | None, path: str | Path,
             error: type[InputError]) -> Any:
    """``value`` as type ``tp``, or _Refused; ``field`` (top-level values only) gives the example in the fix."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if tp is Any or tp is object:
        return value
    if dataclasses.is_dataclass(tp) and isinstance(tp, type):
        return _build(tp, value, where, path, error)
    if origin is Union or origin is types.UnionType:
        if value is None and type(None) in args:
            return None
        options = [a for a in args if a is not type(None)]
        if len(options) == 1:
            try:
                return _convert(options[0], value, where, field, path, error)
            except _Refused as r:
                if r.where != where or type(None) not in args:
                    raise
                raise _Refused(where, value, f"{r.expected} or null", r.fix) from None
        for option in options:
            try:
                return _convert(option, value, where, field, path, error)
            except _Refused:
                continue
        raise _Refused(where, value, " or ".join(_expected(a) for a in args), _fix(tp, value, where, field))
    if origin is Literal:
        if any(value == a and type(value) is type(a) for a in args):
            return value
        raise _Refused(where, value, _expected(tp), _fix(tp, value, where, field))
    if tp is bool:
        if isinstance(value, bool):
            return value
    elif tp is int:
        if isinstance(value, numbers.Integral) and not isinstance(value, bool):  # numpy integers from Python callers
            return int(value)
    elif tp is float:
        if isinstance(value, numbers.Real) and not isinstance(value, bool):
            return float(value)
        if isinstance(value, str) and _EXPONENT_FLOAT.fullmatch(value.strip()):
            return float(value)
    elif tp is str:
        if isinstance(value, str):
            return value
    elif origin is list or origin is tuple:
        if isinstance(value, list | tuple):
            return _sequence(tp, value, where, field, path, error)
    elif origin is dict:
        if isinstance(value, Mapping):
            key_tp, value_tp = args or (Any, Any)
            return {_convert(key_tp, k, f"{where}[{k!r}]", None, path, error):
                    _convert(value_tp, v, f"{where}.{k}", None, path, error) for k, v in value.items()}
    else:
        raise TypeError(f"stages.scene.typed_yaml cannot check type {tp!r} (at {where})")
    raise _Refused(where, value, _expected(tp), _fix(tp, value, where, field))


def _sequence(tp: Any, value: list | tuple, where: str, field: dataclasses.Field | None, path: str | Path,
              error: type[InputError]) -> list | tuple:
    """A list or tuple hint: each item checked; a refused item's fix shows the whole list (its default)."""
    args = typing.get_args(tp)
    if typing.get_origin(tp) is list or (len(args) == 2 and args[1] is Ellipsis):
        items = [args[0] if args else Any] * len(value)
    elif len(value) == len(args):
        items = list(args)
    else:
        raise _Refused(where, value, _expected(tp), _fix(tp, value, where, field))
    try:
        out = [_convert(item, v, f"{where}[{i}]", None, path, error)
               for i, (item, v) in enumerate(zip(items, value, strict=True))]
    except _Refused as r:
        # an item (or an item of an item) of numbers or strings: show the whole list as the example
        if "." not in r.where[len(where):] and not any(dataclasses.is_dataclass(a) for a in items):
            r.fix = _fix(tp, None, where, field)
        raise
    return out if typing.get_origin(tp) is list else tuple(out)


@functools.cache
def _hints(cls: type) -> dict[str, Any]:
    """Resolved field types (the modules use ``from __future__ import annotations``, so field.type is text)."""
    return typing.get_type_hints(cls)


def _fields(cls: type) -> dict[str, dataclasses.Field]:
    if not dataclasses.is_dataclass(cls):
        raise TypeError(f"{cls!r} is not a dataclass")
    return {f.name: f for f in dataclasses.fields(cls) if f.init}


def _required(f: dataclasses.Field) -> bool:
    return f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING


def _join(where: str, key: str) -> str:
    return f"{where}.{key}" if where else key


def _label(where: str) -> str:
    return where or "the top level"


def _show(value: Any) -> str:
    """The value as a user wrote it, with its YAML type when that is the surprise (``'7'`` vs ``7``)."""
    kind = {bool: "a boolean", int: "an integer", float: "a number", str: "a string", type(None): "null",
            list: "a list", dict: "a mapping"}.get(type(value), type(value).__name__)
    return f"{value!r} ({kind})"


def _expected(tp: Any) -> str:
    """A type hint in words."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if tp is type(None):
        return "null"
    if dataclasses.is_dataclass(tp):
        return f"a mapping of {tp.__name__} fields"
    if origin is Literal:
        return f"one of {', '.join(repr(a) for a in args)}"
    if origin is Union or origin is types.UnionType:
        return " or ".join(_expected(a) for a in args)
    if origin is list or (origin is tuple and len(args) == 2 and args[1] is Ellipsis):
        return f"a list of {_plural(args[0]) if args else 'values'}"
    if origin is tuple:
        return f"a list of {len(args)} items ({', '.join(_expected(a) for a in args)})"
    if origin is dict:
        return "a mapping"
    return {bool: "true or false", int: "an integer", float: "a number", str: "a string"}.get(tp, repr(tp))


def _plural(tp: Any) -> str:
    words = {int: "integers", float: "numbers", str: "strings", bool: "booleans"}
    if tp in words:
        return words[tp]
    if dataclasses.is_dataclass(tp):
        return f"mappings of {tp.__name__} fields"
    if typing.get_origin(tp) is list:
        return f"lists of {_plural(typing.get_args(tp)[0])}"
    return f"items that are each {_expected(tp)}"


def _fix(tp: Any, value: Any, where: str, field: dataclasses.Field | None) -> str:
    """What to write instead: the expected type with the field's default as the example, or the fix of the
    YAML quirk that most likely produced ``value`` (an unquoted ``off`` read as false, a quoted number)."""
    if isinstance(value, bool) and _wants_text(tp):
        word = _bool_word(tp, value)
        return (f"quote the word, YAML reads unquoted {_YAML_BOOL_WORDS} as true/false: write {where}: '{word}' "
                f"in a file, --set \"{where}='{word}'\" on the command line")
    if tp is int and isinstance(value, float) and value.is_integer():
        return f"write {where} as an integer: {int(value)}, without a decimal point"
    if tp is str and isinstance(value, int | float):
        return f"write {where} as a string, in quotes: '{value}'"
    example = _example(tp, field)
    fix = f"write {where} as {_expected(tp)}" + (f", e.g. {example}" if example not in ("", "''", "[]", "{}") else "")
    if isinstance(value, str) and tp in (int, float, bool) and _unquoted_fits(value, tp):
        fix += ", without quotes"
    return fix


def _wants_text(tp: Any) -> bool:
    return tp is str or (typing.get_origin(tp) is Literal and any(isinstance(a, str) for a in typing.get_args(tp)))


def _bool_word(tp: Any, value: bool) -> str:
    """The word a user most likely typed for ``value``: a Literal choice YAML turned into a boolean, or yes/no."""
    words = ("on", "yes", "true") if value else ("off", "no", "false")
    choices = [a for a in typing.get_args(tp) if isinstance(a, str) and a.lower() in words]
    return choices[0] if choices else words[1]


def _unquoted_fits(text: str, tp: type) -> bool:
    """Whether ``text`` written without quotes would be read as ``tp``."""
    try:
        value = yaml.safe_load(text)
    except yaml.YAMLError:
        return False
    if tp is float:
        return isinstance(value, int | float) and not isinstance(value, bool)
    return isinstance(value, tp) and (tp is bool or not isinstance(value, bool))


def _example(tp: Any, field: dataclasses.Field | None) -> str:
    """The field's default as YAML (the natural example), else a made-up value of the type; "" for none."""
    default: Any = dataclasses.MISSING
    if field is not None:
        if field.default is not dataclasses.MISSING:
            default = field.default
        elif field.default_factory is not dataclasses.MISSING:
            default = field.default_factory()
    if default is dataclasses.MISSING or default is None or dataclasses.is_dataclass(default):
        default = {int: 3, float: 0.5, bool: True, str: "text"}.get(tp, dataclasses.MISSING)
        if typing.get_origin(tp) is Literal:
            default = typing.get_args(tp)[0]
    if default is dataclasses.MISSING:
        return ""
    return yaml.safe_dump(default, default_flow_style=True, width=1000).removesuffix("...\n").strip()
