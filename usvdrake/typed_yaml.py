"""Typed YAML loading with one-line errors.

Drake's ``yaml_load_typed`` does the actual loading into dataclasses; before it runs, the raw
YAML tree is checked against the schema here so that a bad file stops with one line naming the
file, the dotted key, what was expected and what was found (Drake's own messages name neither
the file nor the full key path).
"""

from __future__ import annotations

import dataclasses
import types
import typing
from pathlib import Path
from typing import Any, TypeVar

from pydrake.common.yaml import yaml_load, yaml_load_typed

from usvdrake.errors import ConfigError

T = TypeVar("T")


def _describe(value: Any) -> str:
    if isinstance(value, dict):
        return "a mapping"
    if isinstance(value, list):
        return "a list"
    if value is None:
        return "nothing (null)"
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _check(tp: Any, value: Any, key: str, file: str) -> None:
    """Raise ConfigError if ``value`` (raw YAML) does not fit type ``tp``."""
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = typing.get_args(tp)
        if value is None and type(None) in args:
            return
        errors = []
        for arg in (a for a in args if a is not type(None)):
            try:
                _check(arg, value, key, file)
                return
            except ConfigError as e:
                errors.append(e.expected)
        raise ConfigError(file, key, " or ".join(errors), _describe(value))
    if dataclasses.is_dataclass(tp):
        if not isinstance(value, dict):
            raise ConfigError(file, key, f"a mapping ({tp.__name__})", _describe(value))
        hints = typing.get_type_hints(tp)
        names = [f.name for f in dataclasses.fields(tp)]
        for k, v in value.items():
            sub = f"{key}.{k}" if key else str(k)
            if k not in hints:
                raise ConfigError(file, sub, "one of " + ", ".join(names), "an unknown key")
            _check(hints[k], v, sub, file)
        return
    if origin is list:
        if not isinstance(value, list):
            raise ConfigError(file, key, "a list", _describe(value))
        (item,) = typing.get_args(tp)
        for i, v in enumerate(value):
            _check(item, v, f"{key}[{i}]", file)
        return
    if origin is dict:
        if not isinstance(value, dict):
            raise ConfigError(file, key, "a mapping", _describe(value))
        _, item = typing.get_args(tp)
        for k, v in value.items():
            _check(item, v, f"{key}.{k}", file)
        return
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(file, key, "a number", _describe(value))
        return
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(file, key, "an integer", _describe(value))
        return
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(file, key, "true or false", _describe(value))
        return
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(file, key, "a string", _describe(value))
        return
    raise TypeError(f"typed_yaml: unsupported schema type {tp!r} at '{key}'")


def load_typed(schema: type[T], filename: str | Path) -> T:
    """Load ``filename`` into a fresh ``schema()``; raise ConfigError with one line on failure."""
    path = Path(filename)
    if not path.is_file():
        raise ConfigError(path, "", "an existing YAML file", "no such file")
    try:
        raw = yaml_load(filename=str(path))
    except Exception as e:  # the YAML parser's messages are multi-line; keep the first line
        first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise ConfigError(path, "", "well-formed YAML", f"a parse error ({first})") from None
    if raw is None:
        raw = {}
    _check(schema, raw, "", str(path))
    return yaml_load_typed(schema=schema, filename=str(path), defaults=schema())


def resolve_yaml(kind: str, name_or_path: str | Path, folder: Path) -> Path:
    """A YAML path as given, or ``folder/NAME.yaml`` for a shipped name (else ConfigError)."""
    path = Path(name_or_path)
    if path.suffix in (".yaml", ".yml"):
        return path
    path = folder / f"{name_or_path}.yaml"
    if not path.is_file():
        names = ", ".join(sorted(p.stem for p in folder.glob("*.yaml")))
        raise ConfigError(kind, "name", f"one of {names}", repr(str(name_or_path)))
    return path


def get_dotted(obj: Any, key: str) -> Any:
    """``get_dotted(scenario, "mission.speed")`` → scenario.mission.speed."""
    for part in key.split("."):
        obj = getattr(obj, part)
    return obj
