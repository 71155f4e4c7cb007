"""Node parameters from scenario values: a frozen `Params` dataclass, checked by its hints.

A scenario gives a node's parameters as YAML values (or Python values of the
same shapes); `build_params` merges them with the scenario's common `params:`,
checks every value against the field's type hint (lists become tuples for tuple
fields, ints become floats for float fields), reads a file parameter
(`runtime.contract.params.file_param`) relative to the scenario's folder and
builds the dataclass. Errors are `ConfigError`s naming the key.
"""

from __future__ import annotations

import dataclasses
import types
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any, NoReturn

from twinfleet.runtime.contract.params import file_fields
from twinfleet.runtime.scenario.config import ConfigError
from twinfleet.runtime.scenario.suggest import did_you_mean


def _fail(key: str, what: str) -> NoReturn:
    raise ConfigError(key, what)


def build_params(params_cls: type, given: Mapping[str, Any], common: Mapping[str, Any],
                 base: Path, where: str) -> Any:
    """Build a frozen Params dataclass from scenario values, checking names and types.

    Args:
        params_cls: the node class's `Params` dataclass.
        given: the node's own values (unknown names are errors).
        common: the scenario's `params:`, used for the fields the class has.
        base: the folder relative file parameters are read from (the scenario file's).
        where: the key errors name, e.g. ``nodes[1].params``.

    Raises:
        ConfigError: naming the key and what was expected.
    """
    fields = {f.name: f for f in dataclasses.fields(params_cls)}
    for key in given:
        if key not in fields:
            expected = ", ".join(fields) or "no parameters"
            _fail(f"{where}.{key}", f"unknown parameter of {params_cls.__name__}; expected "
                  f"{expected}{did_you_mean(key, fields)}")
    values = {k: v for k, v in common.items() if k in fields}
    values.update(given)
    hints = typing.get_type_hints(params_cls)
    converted = {k: _convert(v, hints.get(k, Any), f"{where}.{k}") for k, v in values.items()}
    for name in file_fields(params_cls):
        if isinstance(converted.get(name), str):
            converted[name] = _file(base, converted[name], f"{where}.{name}")
    missing = [f.name for f in fields.values() if f.name not in converted
               and f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING]
    if missing:
        _fail(f"{where}.{missing[0]}", f"missing; {params_cls.__name__} needs {', '.join(missing)}")
    try:
        return params_cls(**converted)
    except (TypeError, ValueError) as exc:
        _fail(where, str(exc))


def _file(base: Path, value: str, key: str) -> str:
    """A file parameter's path, absolute: node processes and the checker read the same file
    wherever they run."""
    path = (base / value).resolve()
    if not path.is_file():
        _fail(key, f"file {path} does not exist")
    return str(path)


def _convert(value: Any, hint: Any, key: str) -> Any:
    """Check a YAML value against a type hint; lists become tuples for tuple fields."""
    origin = typing.get_origin(hint)
    if hint is Any:
        return value
    if origin in (typing.Union, types.UnionType):
        for option in typing.get_args(hint):
            try:
                return _convert(value, option, key)
            except ConfigError:
                continue
        _fail(key, f"expected {_hint_name(hint)}, got {value!r}")
    if hint is type(None):
        if value is None:
            return None
        _fail(key, f"expected null, got {value!r}")
    if origin is tuple:
        if not isinstance(value, list | tuple):
            _fail(key, f"expected a list ({_hint_name(hint)}), got {value!r}")
        args = typing.get_args(hint)
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_convert(v, args[0], f"{key}[{i}]") for i, v in enumerate(value))
        if len(args) != len(value):
            _fail(key, f"expected {len(args)} values ({_hint_name(hint)}), got {value!r}")
        return tuple(_convert(v, a, f"{key}[{i}]") for i, (v, a) in enumerate(zip(value, args, strict=True)))
    if hint is float and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if isinstance(hint, type) and not isinstance(value, hint) or (hint is int and isinstance(value, bool)):
        _fail(key, f"expected {_hint_name(hint)}, got {value!r}")
    return value


def _hint_name(hint: Any) -> str:
    return getattr(hint, "__name__", None) or str(hint).replace("typing.", "")
