"""Typed YAML loading with one-line errors.

Drake's ``yaml_load_typed`` does the actual loading into dataclasses; before it runs, the raw
YAML tree is checked against the schema here so that a bad file stops with one line naming the
file, the dotted key, what was expected and what was found (Drake's own messages name neither
the file nor the full key path). That check reads numbers as YAML 1.2 does (``1e6``, ``1.0e6``,
``.inf`` are numbers; Drake's typed loader then converts them too) and refuses a key given twice
in one mapping, which YAML loaders otherwise accept silently (the last one winning).
"""

from __future__ import annotations

import dataclasses
import re
import types
import typing
from pathlib import Path
from typing import Any, TypeVar

import yaml
from pydrake.common.yaml import yaml_load_typed

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


_FLOAT_TAG = "tag:yaml.org,2002:float"
_MERGE_TAG = "tag:yaml.org,2002:merge"


class _DuplicateKey(Exception):
    def __init__(self, key: Any, line: int):
        super().__init__(key)
        self.key, self.line = key, line


class _StrictLoader(yaml.SafeLoader):
    """PyYAML's SafeLoader with YAML 1.2 (core schema) floats — ``1e6``, ``1.0e6``, ``.inf``,
    ``.nan`` are numbers, as Drake's typed loader then reads them — and duplicate keys refused.
    Tags (``!Variant``) become a ``_tag`` entry, as in Drake's own loader."""

    def construct_mapping(self, node, deep=False):
        if isinstance(node, yaml.MappingNode):
            seen = set()
            for key_node, _ in node.value:
                if key_node.tag == _MERGE_TAG:
                    continue
                key = self.construct_object(key_node, deep=True)
                try:
                    duplicate = key in seen
                except TypeError:  # an unhashable key: SafeLoader reports it
                    continue
                if duplicate:
                    raise _DuplicateKey(key, key_node.start_mark.line + 1)
                seen.add(key)
        return super().construct_mapping(node, deep=deep)


_StrictLoader.yaml_implicit_resolvers = {
    first: [(tag, regexp) for tag, regexp in resolvers if tag != _FLOAT_TAG]
    for first, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()
}
_StrictLoader.add_implicit_resolver(
    _FLOAT_TAG,
    re.compile(
        r"""^(?:[-+]?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)(?:[eE][-+]?[0-9]+)?
        |[-+]?\.(?:inf|Inf|INF)
        |\.(?:nan|NaN|NAN))$""",
        re.X,
    ),
    list("-+0123456789."),
)
_StrictLoader.add_multi_constructor(
    "", lambda loader, tag, node: {**loader.construct_mapping(node), "_tag": tag}
)


MAX_YAML_BYTES = 1 << 20  # a configuration file is a page or two; PyYAML takes ~10 s per 10 MB


def _load_raw(path: Path) -> Any:
    """The YAML tree of ``path`` (root keys starting with ``_`` dropped, as Drake does)."""
    try:
        size = Path(path).stat().st_size
    except OSError as e:
        raise ConfigError(path, "", "a readable file", e.strerror or type(e).__name__) from None
    if size > MAX_YAML_BYTES:
        raise ConfigError(path, "", f"at most {MAX_YAML_BYTES >> 20} MB of YAML", f"{size} bytes")
    try:
        with open(path, encoding="utf-8") as f:
            raw = yaml.load(f, Loader=_StrictLoader)  # noqa: S506 (a SafeLoader subclass)
    except _DuplicateKey as e:
        raise ConfigError(
            path, str(e.key), "each key once in a mapping", f"it again on line {e.line}"
        ) from None
    except Exception as e:  # the YAML parser's messages are multi-line; keep the first line
        first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise ConfigError(path, "", "well-formed YAML", f"a parse error ({first})") from None
    if isinstance(raw, dict):
        raw = {k: v for k, v in raw.items() if not (isinstance(k, str) and k.startswith("_"))}
    return raw


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
    raw = _load_raw(path)
    if raw is None:
        raise ConfigError(path, "", f"a mapping ({schema.__name__})", "an empty document")
    _check(schema, raw, "", str(path))
    return yaml_load_typed(schema=schema, filename=str(path), defaults=schema())


def is_plain_name(name: str | Path) -> bool:
    """A shipped-file name: no path separators, no ``..``, not empty."""
    text = str(name)
    return bool(text) and not any(c in text for c in "/\\\0") and ".." not in text


def resolve_yaml(kind: str, name_or_path: str | Path, folder: Path) -> Path:
    """A YAML path as given (``*.yaml``/``*.yml``), or ``folder/NAME.yaml`` for a shipped name —
    a plain name only, never a path out of ``folder`` (else ConfigError)."""
    path = Path(name_or_path)
    if path.suffix in (".yaml", ".yml"):
        return path
    path = folder / f"{name_or_path}.yaml"
    if not is_plain_name(name_or_path) or not path.is_file():
        names = ", ".join(sorted(p.stem for p in folder.glob("*.yaml")))
        raise ConfigError(kind, "name", f"one of {names}", repr(str(name_or_path)))
    return path


def get_dotted(obj: Any, key: str) -> Any:
    """``get_dotted(scenario, "mission.speed")`` → scenario.mission.speed."""
    for part in key.split("."):
        obj = getattr(obj, part)
    return obj
