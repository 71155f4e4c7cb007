"""Per-class ``__init__``, freeze and thaw, generated as source once per message type.

The rclpy layer freezes every message a callback publishes and every message a
node keeps in its state, and thaws every message it delivers: under the checker
that is the hot path. As `dataclasses` does for ``__init__``, each function is
written out for its class's fields (no loop over converters, no dispatch on the
field's kind per value) and compiled once; `values.Converter` remains the slow
path, reached only for a value that needs converting (an int where a float is
due, a byte) or is wrong (its one-line error).

Field names are ROS 2 field names (lower-case identifiers that start with a
letter), so the names the generated code uses itself all start with ``_``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from twinfleet.interfaces.definitions import Container, FieldType
from twinfleet.interfaces.values import INT_RANGES, Converter, FieldValueError

_FAST_TYPES = {"float32": "float", "float64": "float", "bool": "bool", "string": "str"}
_MISSING = object()


def _scalar_test(t: FieldType, var: str) -> str | None:
    """A Python test that `var` already is a valid value of scalar type `t`, or None."""
    if t.base in _FAST_TYPES:
        test = f"type({var}) is {_FAST_TYPES[t.base]}"
        if t.string_bound:
            test += f" and len({var}) <= {t.string_bound}"
        return test
    if t.base in INT_RANGES:
        low, high = INT_RANGES[t.base]
        return f"type({var}) is int and {low} <= {var} <= {high}"
    return None


def make_init(convs: tuple[Converter, ...], owner: str) -> Callable[..., None]:
    """``__init__(self, *, field=default, ...)`` of a mutable class; an unknown keyword is
    a TypeError naming the fields."""
    params, body, env = [], [], {"_M": _MISSING, "_fields": ", ".join(
        c.field.name for c in convs) or "none", "_owner": owner}
    for i, c in enumerate(convs):
        name, t = c.field.name, c.field.type
        if t.container is Container.ONE and not t.nested:
            env[f"_d{i}"] = c.default()  # immutable: one value serves every instance
            params.append(f"{name}=_d{i}")
            body.append(f"    _s.{name} = {name}")
        else:
            env[f"_f{i}"] = c.default
            params.append(f"{name}=_M")
            body.append(f"    _s.{name} = _f{i}() if {name} is _M else {name}")
    keywords = f"*, {', '.join(params)}, " if params else ""
    source = (f"def __init__(_s, {keywords}**_extra):\n"
              "    if _extra:\n"
              "        raise TypeError(f'{_owner} has no field {sorted(_extra)[0]!r} "
              "(fields: {_fields})')\n" + "\n".join(body or ["    pass"]) + "\n")
    return _compile(source, "__init__", env)


def make_freeze(convs: tuple[Converter, ...], ros_type: str, frozen: type, mutable: Any,
                freeze_of: Callable[[str], Callable[[Any, str], Any]],
                slow: Callable[[Any, str, Converter], Any]) -> Callable[[Any, str], Any]:
    """``freeze(msg, where)``: the frozen message of a mutable one of exactly this class.

    `freeze_of(ros_type)` gives a nested type's function; `slow(value, where, converter)`
    converts or refuses a value the fast tests do not pass.
    """
    env: dict[str, Any] = {"_F": frozen, "_C": mutable, "_slow": slow, "_tuple": tuple,
                           "_list": list, "_Err": FieldValueError, "_T": ros_type}
    lines = ["def _freeze(_m, _w):",
             "    if type(_m) is not _C:",
             "        if type(_m) is _F:",
             "            return _m",
             "        raise _Err(f'{_w}: expected a {_T}, got {type(_m).__name__}')"]
    args = []
    for i, c in enumerate(convs):
        name, t, var = c.field.name, c.field.type, f"_v{i}"
        env[f"_c{i}"] = c
        lines.append(f"    {var} = _m.{name}")
        if t.container is Container.ONE and t.nested:
            env[f"_n{i}"] = freeze_of(t.base)
            lines.append(f"    {var} = _n{i}({var}, _w + '.{name}')")
        elif t.container is Container.ONE:
            test = _scalar_test(t, var)
            fix = f"{var} = _slow({var}, _w, _c{i})"
            lines.append(f"    if not ({test}):\n        {fix}" if test else f"    {fix}")
        else:
            lines += _sequence(t, var, i)
        args.append(var)
    lines.append(f"    return _F({', '.join(args)})")
    return _compile("\n".join(lines) + "\n", "_freeze", env)


def _sequence(t: FieldType, var: str, i: int) -> list[str]:
    """Freeze a list field: a list or tuple of valid values becomes a tuple as it is."""
    test = None if t.nested else _scalar_test(t, "_x")
    if test is None:
        return [f"    {var} = _slow({var}, _w, _c{i})"]
    size = (f"len(_t) == {t.size} and " if t.container is Container.ARRAY else
            f"len(_t) <= {t.size} and " if t.size else "")
    return [f"    if type({var}) is _list or type({var}) is _tuple:",
            f"        _t = _tuple({var})",
            f"        {var} = _t if {size}all({test} for _x in _t) else _slow(_t, _w, _c{i})",
            "    else:",
            f"        {var} = _slow({var}, _w, _c{i})"]


def make_thaw(convs: tuple[Converter, ...], mutable: Any,
              thaw_of: Callable[[str], Callable[[Any], Any]]) -> Callable[[Any], Any]:
    """``thaw(frozen)``: a new mutable message (new lists, new nested messages)."""
    env: dict[str, Any] = {"_C": mutable, "_new": object.__new__, "_list": list}
    lines = ["def _thaw(_f):", "    _m = _new(_C)"]
    for i, c in enumerate(convs):
        name, t = c.field.name, c.field.type
        if t.nested:
            env[f"_n{i}"] = thaw_of(t.base)
            value = (f"_n{i}(_f.{name})" if t.container is Container.ONE
                     else f"[_n{i}(_x) for _x in _f.{name}]")
        else:
            value = f"_f.{name}" if t.container is Container.ONE else f"_list(_f.{name})"
        lines.append(f"    _m.{name} = {value}")
    lines.append("    return _m")
    return _compile("\n".join(lines) + "\n", "_thaw", env)


def _compile(source: str, name: str, env: dict[str, Any]) -> Any:
    namespace: dict[str, Any] = {}
    exec(compile(source, f"<twinfleet.interfaces {name}>", "exec"), env, namespace)  # noqa: S102
    return namespace[name]
