"""A typed configuration as TOML: frozen dataclasses in, frozen dataclasses out.

Every tuning value of wallmap lives in a dataclass with a default and a documented meaning; the
whole configuration is one tree of them (``wallmap.config.Config``). This module turns such a
tree into plain values and TOML (``wallmap config`` prints it, runs write it beside their
outputs) and back, checking every value against the field's type, so a typo in a file or in
``--set detector.ransac.noise_k=2e-3`` is one readable error naming the key, never a surprise
deep in a service. Pure: no wallmap type is known here.

Conventions: ``None`` (unset) is left out of a file, and a key left out keeps its default, so a
file printed by ``wallmap config`` reads back to the same configuration. A field whose metadata
has ``config=False`` is not configuration (it is decided per command) and is neither written
nor read.
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
import textwrap
import tomllib
import types
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Literal, TypeVar, Union, get_args, get_origin, get_type_hints

import numpy as np

T = TypeVar("T")
Tree = dict[str, Any]


def require(ok: bool, name: str, rule: str, value: object) -> None:
    """A dataclass's check of one value: ``NAME must be RULE, got VALUE`` unless ``ok``.

    Raised from ``__post_init__``, so a configuration file, ``--set`` and a flag are held to
    the same rule, and ``from_tree`` names the section.
    """
    if not ok:
        msg = f"{name} must be {rule}, got {value!r}"
        raise ValueError(msg)


class ConfigError(ValueError):
    """A configuration value, key or file that cannot be used; the message names it."""


def _fields(cls: type) -> list[dataclasses.Field[Any]]:
    return [f for f in dataclasses.fields(cls) if f.metadata.get("config", True)]


# --- dataclasses <-> plain values --------------------------------------------------------------


def to_tree(obj: Any) -> Any:
    """A dataclass tree as plain values (dicts, lists, numbers, strings); ``None`` left out."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        tree = {}
        for f in _fields(type(obj)):
            value = to_tree(getattr(obj, f.name))
            if value is not None:
                tree[f.name] = value
        return tree
    if isinstance(obj, tuple | list):
        return [to_tree(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


def from_tree(cls: type[T], tree: Any, where: str = "") -> T:
    """The dataclass ``cls`` from plain values; keys left out keep their defaults.

    Raises:
        ConfigError: an unknown key, or a value of the wrong type, named by its dotted path.
    """
    if not isinstance(tree, Mapping):
        raise ConfigError(f"{where or 'the configuration'} must be a table, got {tree!r}")
    hints = get_type_hints(cls)
    fields = {f.name: f for f in _fields(cls)}
    unknown = sorted(set(tree) - set(fields))
    if unknown:
        known = ", ".join(sorted(fields))
        raise ConfigError(f"unknown key {_join(where, unknown[0])!r} (known here: {known})")
    values = {
        name: _convert(hints[name], value, _join(where, name)) for name, value in tree.items()
    }
    try:
        return cls(**values)
    except (TypeError, ValueError) as err:
        raise ConfigError(f"{where or 'the configuration'}: {err}") from err


def _join(where: str, name: str) -> str:
    return f"{where}.{name}" if where else name


def _convert(tp: Any, value: Any, where: str) -> Any:
    origin, args = get_origin(tp), get_args(tp)
    if tp is Any:
        return value
    if origin in (Union, types.UnionType):
        return _convert_union(args, value, where)
    if dataclasses.is_dataclass(tp):
        return from_tree(tp, value, where)
    if origin is Literal:
        if value not in args:
            raise ConfigError(f"{where} must be one of {', '.join(map(repr, args))}, got {value!r}")
        return value
    if origin is tuple:
        return _convert_tuple(args, value, where)
    if tp is np.ndarray or origin is np.ndarray:
        return _convert_array(value, where)
    if tp in (bool, int, float, str, Path):
        return _convert_scalar(tp, value, where)
    raise ConfigError(f"{where}: no configuration reads values of type {tp!r}")


def _convert_union(args: tuple[Any, ...], value: Any, where: str) -> Any:
    if value is None and type(None) in args:
        return None
    errors = []
    for option in (a for a in args if a is not type(None)):
        try:
            return _convert(option, value, where)
        except ConfigError as err:
            errors.append(err)
    raise errors[0]


def _convert_tuple(args: tuple[Any, ...], value: Any, where: str) -> tuple[Any, ...]:
    if not isinstance(value, list | tuple):
        raise ConfigError(f"{where} must be a list, got {value!r}")
    if len(args) == 2 and args[1] is Ellipsis:
        return tuple(_convert(args[0], v, f"{where}[{i}]") for i, v in enumerate(value))
    if len(value) != len(args):
        raise ConfigError(f"{where} must hold {len(args)} values, got {len(value)}")
    pairs = enumerate(zip(args, value, strict=True))
    return tuple(_convert(a, v, f"{where}[{i}]") for i, (a, v) in pairs)


def _convert_array(value: Any, where: str) -> np.ndarray:
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ConfigError(f"{where} must be numbers, got {value!r}") from None
    if not np.isfinite(array).all():
        raise ConfigError(f"{where} must be finite numbers, got {value!r}")
    return array


def _convert_scalar(tp: type, value: Any, where: str) -> Any:
    if tp is bool and isinstance(value, bool):
        return value
    if tp is int and isinstance(value, int) and not isinstance(value, bool):
        return value
    if tp is float and isinstance(value, int | float) and not isinstance(value, bool):
        if math.isnan(value):
            raise ConfigError(f"{where} must be a number, got nan")
        return float(value)
    if tp is str and isinstance(value, str):
        return value
    if tp is Path and isinstance(value, str | Path):
        return Path(value)
    kind = {bool: "true or false", int: "an integer", float: "a number"}.get(tp, "a string")
    raise ConfigError(f"{where} must be {kind}, got {value!r}")


# --- trees: merging, dotted assignments ----------------------------------------------------------


def merge(base: Tree, over: Mapping[str, Any]) -> Tree:
    """``base`` with ``over`` laid on top, table by table (``over`` wins)."""
    out = dict(base)
    for key, value in over.items():
        if isinstance(value, Mapping) and isinstance(out.get(key), Mapping):
            out[key] = merge(out[key], value)
        else:
            out[key] = value
    return out


_KEY = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*$")


def assignment(text: str) -> Tree:
    """``section.key=value`` as a tree; the value is read as TOML, else taken as a string.

    So ``--set detector.seed=3`` gives an integer, ``--set player.source.pose_source=odom`` a
    string, ``--set detector.rows.band=[1.0,1.8]`` a list.
    """
    key, sep, raw = text.partition("=")
    key = key.strip()
    if not sep or not _KEY.match(key):
        raise ConfigError(f"expected SECTION.KEY=VALUE, got {text!r}")
    try:
        value = tomllib.loads(f"v = {raw.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw.strip()
    tree: Tree = {}
    node = tree
    *parents, last = key.split(".")
    for name in parents:
        node = node.setdefault(name, {})
    node[last] = value
    return tree


def load(path: Path) -> Tree:
    """A TOML file as a tree; ConfigError says why it cannot be read."""
    try:
        return tomllib.loads(Path(path).read_text(encoding="utf-8"))
    except OSError as err:
        raise ConfigError(f"cannot read the configuration {path}: {err.strerror}") from err
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as err:
        raise ConfigError(f"{path} is not TOML: {err}") from err


# --- TOML out ----------------------------------------------------------------------------------


def field_docs(cls: type) -> dict[str, str]:
    """Each attribute's description in ``cls``'s Google-style docstring, as one line."""
    docs: dict[str, str] = {}
    name = None
    in_attributes = False
    for line in (cls.__doc__ or "").splitlines():
        stripped = line.strip()
        if stripped == "Attributes:":
            in_attributes = True
            continue
        indent = len(line) - len(line.lstrip())
        match = re.match(r"^(\w+)(?: \(.*\))?: (.*)$", stripped)
        if not in_attributes or not stripped:
            name = None
        elif match and indent <= 8:
            name = match.group(1)
            docs[name] = match.group(2)
        elif name is not None and indent > 8:
            docs[name] += " " + stripped
    return {key: text.replace("``", "`") for key, text in docs.items()}


def dumps(obj: Any) -> str:
    """The dataclass tree ``obj`` as TOML, each key under a comment saying what it is."""
    lines: list[str] = []
    _table(obj, [], lines)
    return "\n".join(lines).strip() + "\n"


def _table(obj: Any, path: list[str], lines: list[str]) -> None:
    docs = field_docs(type(obj))
    subtables = []
    if path:
        lines += ["", f"[{'.'.join(path)}]"]
        if doc := (type(obj).__doc__ or "").strip().splitlines()[0:1]:
            lines.append("# " + doc[0].replace("``", "`"))
    for f in _fields(type(obj)):
        value = getattr(obj, f.name)
        if dataclasses.is_dataclass(value):
            subtables.append((f.name, value))
            continue
        if doc := docs.get(f.name):
            lines += textwrap.wrap(doc, 98, initial_indent="# ", subsequent_indent="# ")
        tree = to_tree(value)
        lines.append(f"# {f.name} is not set" if tree is None else f"{f.name} = {_value(tree)}")
    for name, value in subtables:
        _table(value, [*path, name], lines)


def _value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, int):
        return str(value)
    if isinstance(value, str):
        return json.dumps(value)  # a JSON string is a TOML basic string
    if isinstance(value, list):
        return "[" + ", ".join(_value(v) for v in value) + "]"
    raise ConfigError(f"cannot write {value!r} as TOML")
