"""What a node lets in: signed, bounded, well-typed samples only (pure logic, no I/O).

Trust model (README "Trust model"). A fleet is a set of processes started by one
launcher. Each launch draws a fresh *fleet key* (32 random bytes) and hands it
to its nodes in the environment (``TWINFLEET_FLEET_KEY``, hex; never on a
command line, which other users can read in ``ps``) and to the owner's monitors
through the owner-only fleet registry. Every sample a fleet member publishes
carries, as its Zenoh attachment, ``HMAC-SHA256(key, key_expr NUL payload)``
cut to 16 bytes; binding the key expression stops a captured ``/r1/status``
being replayed as a ``/collisions``. A receiver with the key drops and counts
(``rejected_forged``) any sample whose tag is missing or wrong, before it is
decoded, so nothing an outsider publishes reaches a handler, the run report or
the shutdown topic — whatever router the fleet runs on.

External input. A fleet launched with a bridge to another system (``launch --ros2``)
draws a second key, the *bridge key* (``TWINFLEET_BRIDGE_KEY``), which only the bridge
signs with. A node accepts a sample signed with it only on the topics its class
declares ``external_topics`` (a robot's ``goal``), and counts it (``external_input``):
the bridge cannot pose as a fleet node (it does not sign with the fleet key, and its
key opens no other topic), and the live verdict says the run took external input.

Bounds. A sample larger than its topic's limit is dropped and counted
(``rejected_oversize``) before it is copied or decoded; the default limit is
sized to the largest legitimate message of the scenario (the occupancy grid),
and the router's ``transport/link/rx/max_message_size`` is set to the same
figure. A decoded message is checked against its class's field annotations
(`validator`): bools, ints, finite floats, strings, bytes, tuples of the
declared length, nested messages; a failure is ``rejected_invalid``. A message
of another type than the handler's annotation declares is
``rejected_wrong_type``. Neither reaches a handler.
"""

from __future__ import annotations

import dataclasses
import hmac
import inspect
import math
import os
import secrets
import types
import typing
from collections.abc import Callable, Mapping
from typing import Any, Final, final

from twinfleet.runtime.contract.messages import DecodeError
from twinfleet.runtime.core.statistics import Rejection

KEY_ENV: Final = "TWINFLEET_FLEET_KEY"
BRIDGE_KEY_ENV: Final = "TWINFLEET_BRIDGE_KEY"
TAG_BYTES: Final = 16
DEFAULT_LIMIT: Final = 256 * 1024  # bytes: far above any pose, scan, path or status
_SEP: Final = b"\0"

Check = Callable[[Any], None]


class Rejected(DecodeError):
    """A decoded sample that does not fit its topic; `reason` says which counter it goes to."""

    def __init__(self, reason: Rejection, text: str) -> None:
        super().__init__(text)
        self.reason = reason


# ------------------------------------------------------------------ the fleet key


def new_key() -> bytes:
    """A fresh fleet key."""
    return secrets.token_bytes(32)


def key_from_env(env: Mapping[str, str] | None = None, name: str = KEY_ENV) -> bytes | None:
    """The fleet key (or, with `name` = `BRIDGE_KEY_ENV`, the bridge key) the launcher passed
    in the environment, or None (an unsigned fleet; a fleet without a bridge).

    Raises:
        ValueError: the variable is set but is not hex.
    """
    text = (os.environ if env is None else env).get(name, "")
    if not text:
        return None
    try:
        return bytes.fromhex(text)
    except ValueError:
        raise ValueError(f"{name} must be hex, got {len(text)} other characters") from None


def sign(key: bytes, key_expr: str, payload: bytes) -> bytes:
    """The attachment that proves `payload` on `key_expr` comes from a holder of `key`."""
    return hmac.digest(key, key_expr.encode() + _SEP + payload, "sha256")[:TAG_BYTES]


def authentic(key: bytes, key_expr: str, payload: bytes, tag: bytes | None) -> bool:
    """True when `tag` is `sign(key, key_expr, payload)` (compared in constant time)."""
    return tag is not None and hmac.compare_digest(sign(key, key_expr, payload), tag)


def signer(key: bytes | None, key_expr: str) -> Callable[[bytes], bytes | None]:
    """A function payload → attachment for one key expression (None without a key)."""
    if key is None:
        return lambda _payload: None
    prefix = key_expr.encode() + _SEP
    return lambda payload: hmac.digest(key, prefix + payload, "sha256")[:TAG_BYTES]


# ------------------------------------------------------------------ payload limits


def payload_limit(width: int, height: int, configured: int | None = None) -> int:
    """The default per-topic payload limit for a map of `width` x `height` cells.

    The occupancy grid (one byte per cell plus a small envelope) is the largest
    message the shipped nodes send; twice its size leaves room for headers.
    """
    if configured is not None:
        return configured
    return max(DEFAULT_LIMIT, 2 * width * height + 4096)


# ------------------------------------------------------------------ typed messages


_VALIDATORS: dict[type, Check] = {}


def validator(cls: type) -> Check:
    """A function that raises `Rejected` (`Rejection.INVALID`) unless a `cls` instance's fields
    fit their annotations (cached per class; a field with an annotation it cannot read
    is not checked)."""
    check = _VALIDATORS.get(cls)
    if check is None:
        _VALIDATORS[cls] = _accept  # a message class that contains itself
        check = _VALIDATORS[cls] = _message_check(cls)
    return check


def check_message(msg: Any) -> None:
    """Validate a decoded message (of any registered class) against its annotations."""
    if dataclasses.is_dataclass(msg) and not isinstance(msg, type):
        validator(type(msg))(msg)


def _accept(_value: Any) -> None:
    return None


def _message_check(cls: type) -> Check:
    try:
        hints = typing.get_type_hints(cls)
    except Exception:  # an annotation that names something not importable here
        return _accept
    checks = [(f.name, _check_for(hints.get(f.name, Any))) for f in dataclasses.fields(cls)]
    name = getattr(cls, "__message_type__", cls.__name__)

    def check(msg: Any) -> None:
        if type(msg) is not cls:
            raise Rejected(Rejection.INVALID, f"{name}: expected a message, got {msg!r:.60}")
        for field, field_check in checks:
            try:
                field_check(getattr(msg, field))
            except Rejected as exc:
                raise Rejected(Rejection.INVALID, f"{name}.{field}: {exc}") from None

    return check


def _bad(value: Any, what: str) -> Rejected:
    return Rejected(Rejection.INVALID, f"expected {what}, got {value!r:.60}")


def _check_for(hint: Any) -> Check:
    """The check of one annotation (`_scalar_check` for plain types)."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin is tuple:
        return _tuple_check(args)
    if origin in (typing.Union, types.UnionType):
        options = [_check_for(a) for a in args]
        return lambda value: _any_of(options, value, hint)
    if isinstance(hint, type) and dataclasses.is_dataclass(hint):
        return lambda value: validator(hint)(value)
    return _scalar_check(hint)


def _scalar_check(hint: Any) -> Check:
    def check_int(value: Any) -> None:
        if type(value) is not int:
            raise _bad(value, "an integer")

    def check_float(value: Any) -> None:
        if type(value) not in (int, float) or not math.isfinite(value):
            raise _bad(value, "a finite number")

    def exact(kind: type, what: str) -> Check:
        def check(value: Any) -> None:
            if type(value) is not kind:
                raise _bad(value, what)
        return check

    table: dict[Any, Check] = {int: check_int, float: check_float, bool: exact(bool, "a bool"),
                               str: exact(str, "a string"), bytes: exact(bytes, "bytes"),
                               type(None): exact(type(None), "None")}
    return table.get(hint, _accept)


def _tuple_check(args: tuple[Any, ...]) -> Check:
    if len(args) == 2 and args[1] is Ellipsis:
        item = _check_for(args[0])

        def check_all(value: Any) -> None:
            if type(value) is not tuple:
                raise _bad(value, "a sequence")
            for v in value:
                item(v)
        return check_all
    if args and all(a is int for a in args):  # cells and the like: the hot case, in one pass
        size = len(args)

        def check_ints(value: Any) -> None:
            if type(value) is not tuple or len(value) != size or not all(
                    type(v) is int for v in value):
                raise _bad(value, f"{size} integers")
        return check_ints
    items = [_check_for(a) for a in args]

    def check_fixed(value: Any) -> None:
        if type(value) is not tuple or len(value) != len(items):
            raise _bad(value, f"{len(items)} values")
        for check, v in zip(items, value, strict=True):
            check(v)
    return check_fixed


def _any_of(options: list[Check], value: Any, hint: Any) -> None:
    for option in options:
        try:
            option(value)
            return
        except Rejected:
            continue
    raise _bad(value, str(hint).replace("typing.", ""))


def expected_type(node: Any, method: str) -> type | None:
    """The message class a handler ``fn(self, ctx, msg: Cls)`` of `node` (an instance or
    its class) declares, or None."""
    fn = getattr(node if isinstance(node, type) else type(node), method, None)
    if fn is None:
        return None
    try:
        params = list(inspect.signature(fn).parameters.values())
        hints = typing.get_type_hints(fn)
    except Exception:  # unreadable annotations: no type check for this handler
        return None
    if len(params) < 3:
        return None
    hint = hints.get(params[2].name)
    return hint if isinstance(hint, type) and hasattr(hint, "__message_type__") else None


@final
class Admission:
    """The checks one subscription's decoded samples pass before they reach the handler.

    Args:
        expected: the message class the handler declares (None: any registered type).
    """

    __slots__ = ("expected",)

    def __init__(self, expected: type | None) -> None:
        self.expected = expected

    def __call__(self, msg: Any) -> None:
        """Raise `Rejected` for a message of the wrong type or with invalid fields."""
        expected = self.expected
        if expected is not None and type(msg) is not expected:
            raise Rejected(Rejection.WRONG_TYPE,
                           f"{getattr(type(msg), '__message_type__', type(msg).__name__)} where "
                           f"{expected.__message_type__} is expected")  # type: ignore[attr-defined]
        check_message(msg)
