"""Frozen-dataclass configs built from YAML, with one-line errors that name the field.

Every config section is a frozen dataclass whose field names carry units
(``mass_kg``, ``sigma_acc_m_s2``). ``build(cls, mapping, where)`` checks for unknown and
missing keys and for types, recursing into nested dataclasses, tuples and lists, and
raises ``ConfigError("file.yaml: estimator.eta: expected a number, got 'abc'")``.
A class may define ``validate(self) -> None`` raising ``ValueError`` for range checks;
the message is prefixed with the field path.
"""

from __future__ import annotations

import dataclasses
import math
import types
import typing
from pathlib import Path
from typing import Any, TypeVar

import yaml

from companion.errors import ConfigError

__all__ = ["ConfigError", "build", "load_yaml"]

T = TypeVar("T")

MAX_YAML_BYTES = 4 * 1024 * 1024  # a mission or config file larger than this is refused unread
MAX_YAML_DEPTH = 32  # nesting levels of mappings/lists (missions need about 5)


def load_yaml(path: str | Path) -> dict[str, Any]:
    """Read a YAML mapping, turning every failure into a one-line ConfigError (size and nesting
    depth limited: ``MAX_YAML_BYTES``, ``MAX_YAML_DEPTH``)."""
    p = Path(path)
    try:
        if p.is_file() and p.stat().st_size > MAX_YAML_BYTES:
            raise ConfigError(f"{p}: {p.stat().st_size:,} bytes; the limit is {MAX_YAML_BYTES:,}")
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"{p}: cannot read: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise ConfigError(f"{p}: not UTF-8 text") from None
    if _nesting_depth(text) > MAX_YAML_DEPTH:
        raise ConfigError(f"{p}: nested deeper than the limit of {MAX_YAML_DEPTH} levels")
    try:
        data = yaml.safe_load(text)
    except RecursionError:
        raise ConfigError(f"{p}: nested deeper than the limit of {MAX_YAML_DEPTH} levels") from None
    except (ValueError, OverflowError) as exc:  # e.g. a timestamp or number YAML cannot represent
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ConfigError(f"{p}: invalid YAML: {first}") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" (line {mark.line + 1})" if mark is not None else ""
        problem = getattr(exc, "problem", None) or "invalid YAML"
        raise ConfigError(f"{p}: invalid YAML{where}: {problem}") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{p}: expected a mapping at the top level")
    if _object_depth(data) > MAX_YAML_DEPTH:  # block-style nesting, anchors and aliases
        raise ConfigError(f"{p}: nested deeper than the limit of {MAX_YAML_DEPTH} levels")
    return data


def _nesting_depth(text: str) -> int:
    """Deepest flow-style bracket nesting (``[[[...`` / ``{{{...``), ignoring quoted text: a cheap
    guard before the parser, whose recursion such input would exhaust."""
    depth = deepest = 0
    quote = ""
    for ch in text:
        if quote:
            if ch == quote:
                quote = ""
        elif ch in "\"'":
            quote = ch
        elif ch in "[{":
            depth += 1
            deepest = max(deepest, depth)
        elif ch in "]}":
            depth = max(depth - 1, 0)
        elif ch == "\n":
            quote = ""
    return deepest


def _object_depth(data: Any) -> int:
    """Nesting depth of parsed YAML (iterative; shared aliases are visited once per path)."""
    deepest = 0
    stack: list[tuple[Any, int]] = [(data, 1)]
    seen = 0
    while stack:
        obj, depth = stack.pop()
        seen += 1
        if seen > 1_000_000:  # a "billion laughs" of aliases
            return MAX_YAML_DEPTH + 1
        if isinstance(obj, dict):
            deepest = max(deepest, depth)
            if depth <= MAX_YAML_DEPTH:
                stack.extend((v, depth + 1) for v in obj.values())
        elif isinstance(obj, list):
            deepest = max(deepest, depth)
            if depth <= MAX_YAML_DEPTH:
                stack.extend((v, depth + 1) for v in obj)
    return deepest


def build(cls: type[T], data: Any, where: str = "") -> T:
    """Build dataclass ``cls`` from ``data`` (a mapping), validating keys and types."""
    return typing.cast(T, _convert(cls, data, where or cls.__name__))


def _convert(tp: Any, value: Any, where: str) -> Any:
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if dataclasses.is_dataclass(tp) and isinstance(tp, type):
        return _build_dataclass(tp, value, where)
    if origin in (typing.Union, types.UnionType):
        errors = []
        if value is None and type(None) in args:
            return None
        for arg in args:
            if arg is type(None):
                continue
            try:
                return _convert(arg, value, where)
            except ConfigError as exc:
                errors.append(str(exc))
        raise ConfigError(errors[0] if errors else f"{where}: unexpected value {value!r}")
    if origin is typing.Literal:
        if value not in args:
            raise ConfigError(f"{where}: expected one of {list(args)}, got {value!r}")
        return value
    if origin in (tuple, list):
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{where}: expected a list, got {value!r}")
        if origin is tuple and args and args[-1] is not Ellipsis:
            if len(value) != len(args):
                raise ConfigError(f"{where}: expected {len(args)} items, got {len(value)}")
            pairs = enumerate(zip(args, value, strict=True))
            items = [_convert(a, v, f"{where}[{i}]") for i, (a, v) in pairs]
        else:
            item_tp = args[0] if args else Any
            items = [_convert(item_tp, v, f"{where}[{i}]") for i, v in enumerate(value)]
        return tuple(items) if origin is tuple else items
    if origin is dict:
        if not isinstance(value, dict):
            raise ConfigError(f"{where}: expected a mapping, got {value!r}")
        vt = args[1] if args else Any
        return {str(k): _convert(vt, v, f"{where}.{k}") for k, v in value.items()}
    if tp is Any:
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{where}: expected a number, got {value!r}")
        if not math.isfinite(value):
            raise ConfigError(f"{where}: expected a finite number, got {value!r}")
        return float(value)
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{where}: expected an integer, got {value!r}")
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{where}: expected true or false, got {value!r}")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"{where}: expected a string, got {value!r}")
        return value
    raise ConfigError(f"{where}: unsupported field type {tp!r}")  # a programming error, said plainly


def _build_dataclass(cls: type, value: Any, where: str) -> Any:
    if not isinstance(value, dict):
        raise ConfigError(f"{where}: expected a mapping, got {value!r}")
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    unknown = sorted(set(map(str, value)) - set(fields))
    if unknown:
        raise ConfigError(f"{where}: unknown key {unknown[0]!r} (known: {', '.join(sorted(fields))})")
    kwargs = {}
    for name, f in fields.items():
        if name in value:
            kwargs[name] = _convert(hints[name], value[name], f"{where}.{name}")
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise ConfigError(f"{where}: missing key {name!r}")
    obj = cls(**kwargs)
    check = getattr(obj, "validate", None)
    if callable(check):
        try:
            check()
        except ValueError as exc:
            raise ConfigError(f"{where}: {exc}") from None
    return obj
