"""What a node lets in: signed, bounded, well-typed samples only (pure logic, no I/O).

Trust model (README "Trust model"). A fleet is a set of processes started by one
launcher. Each launch draws a fresh *fleet key* (32 random bytes) and hands it
to its nodes in the environment (``TWINFLEET_FLEET_KEY``, hex; never on a
command line, which other users can read in ``ps``) and to the owner's monitors
through the owner-only fleet registry. Every sample a fleet member publishes
carries, as its Zenoh attachment, a tag and a *stamp*: the stamp is the sender's
role, its sender id (64 random bits drawn once per publisher) and a sequence number
(one more per sample); the tag is ``HMAC-SHA256(key, key_expr NUL stamp payload)``
cut to 16 bytes. Binding the key expression stops a captured ``/r1/status``
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

Replays. A holder of a login (an insider, or a captured sample) could still send a
signed sample again. Each subscription keeps a `ReplayWindow`: per (key expression,
sender id), the highest sequence number seen and which of the `WINDOW` before it
arrived; a sample whose number was seen, or is older than the window, is dropped and
counted (``rejected_replayed``). The stamp is signed, so a replayed sample cannot be
renumbered. A receiver that meets a sender id for the first time takes its first
sample as new (it cannot know what it missed), so one replay per sender may reach a
receiver that joins after the sender started; never more, and never twice.

Roles. The stamp's role says who signed: a fleet member (`Role.MEMBER`), or
``twinfleet play --into-fleet`` injecting recorded input (`Role.RECORDED`), which a
node accepts only when its fleet was launched to (``--accept-recorded``) and
otherwise drops and counts (``rejected_recorded``).

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
import itertools
import math
import secrets
import struct
import threading
import types
import typing
from collections.abc import Callable, Mapping
from enum import IntEnum, unique
from typing import Any, Final, NamedTuple, final

from twinfleet.runtime.contract.dispatch import wrong_type_line
from twinfleet.runtime.contract.environment import EnvVar, env_value
from twinfleet.runtime.contract.messages import DecodeError
from twinfleet.runtime.contract.names import OPERATOR_SENDER
from twinfleet.runtime.core.statistics import Rejection

KEY_ENV: Final = EnvVar.FLEET_KEY
BRIDGE_KEY_ENV: Final = EnvVar.BRIDGE_KEY
TAG_BYTES: Final = 16
DEFAULT_LIMIT: Final = 256 * 1024  # bytes: far above any pose, scan, path or status
_SEP: Final = b"\0"
_STAMP: Final = struct.Struct(">BQQ")  # role, sender id, sequence number
ATTACHMENT_BYTES: Final = TAG_BYTES + _STAMP.size
WINDOW: Final = 1024  # sequence numbers a `ReplayWindow` remembers per sender
_SENDERS: Final = 4096  # sender ids a `ReplayWindow` remembers (the oldest go first)


@unique
class Role(IntEnum):
    """Who signed a sample (module docstring)."""

    MEMBER = 0  # a node, the launcher, the owner's operator commands
    RECORDED = 1  # `twinfleet play --into-fleet`: recorded input injected on purpose


class Stamp(NamedTuple):
    """The signed part of an attachment besides the payload: who sent it and its number."""

    role: Role
    sender: int
    sequence: int

Check = Callable[[Any], None]


class Rejected(DecodeError):
    """A decoded sample that does not fit its topic; `reason` says which counter it goes to."""

    def __init__(self, reason: Rejection, text: str, *, first: bool | None = None) -> None:
        super().__init__(text)
        self.reason = reason
        # For a message of the wrong type: whether it is the first of its sender and topic
        # (its line is shown once, the rest counted); None for other reasons.
        self.first = first


# ------------------------------------------------------------------ the fleet key


def new_key() -> bytes:
    """A fresh fleet key."""
    return secrets.token_bytes(32)


def key_from_env(env: Mapping[str, str] | None = None, name: EnvVar = KEY_ENV) -> bytes | None:
    """The fleet key (or, with `name` = `BRIDGE_KEY_ENV`, the bridge key) the launcher passed
    in the environment, or None (an unsigned fleet; a fleet without a bridge).

    Raises:
        ValueError: the variable is set but is not hex.
    """
    text = env_value(name, env) or ""
    if not text:
        return None
    try:
        return bytes.fromhex(text)
    except ValueError:
        raise ValueError(f"{name} must be hex, got {len(text)} other characters") from None


def _tag(key: bytes, key_expr: bytes, stamp: bytes, payload: bytes) -> bytes:
    return hmac.digest(key, key_expr + _SEP + stamp + payload, "sha256")[:TAG_BYTES]


def sign(key: bytes, key_expr: str, payload: bytes, role: Role = Role.MEMBER) -> bytes:
    """The attachment of one sample on `key_expr` from a holder of `key`: a sender of its
    own (a fresh sender id), number 0. A stream of samples takes a `signer`."""
    stamp = _STAMP.pack(role, secrets.randbits(64), 0)
    return _tag(key, key_expr.encode(), stamp, payload) + stamp


def opened(key: bytes, key_expr: str, payload: bytes, attachment: bytes | None) -> Stamp | None:
    """The stamp of `attachment` if it proves `payload` on `key_expr` comes from a holder of
    `key` (compared in constant time), else None."""
    if attachment is None or len(attachment) != ATTACHMENT_BYTES:
        return None
    tag, stamp = attachment[:TAG_BYTES], attachment[TAG_BYTES:]
    if not hmac.compare_digest(_tag(key, key_expr.encode(), stamp, payload), tag):
        return None
    role, sender, sequence = _STAMP.unpack(stamp)
    try:
        return Stamp(Role(role), sender, sequence)
    except ValueError:  # a role this version does not know
        return None


def authentic(key: bytes, key_expr: str, payload: bytes, tag: bytes | None) -> bool:
    """True when `tag` is a valid attachment of `payload` on `key_expr` under `key`."""
    return opened(key, key_expr, payload, tag) is not None


def signer(key: bytes | None, key_expr: str,
           role: Role = Role.MEMBER) -> Callable[[bytes], bytes | None]:
    """A function payload → attachment for one sender on one key expression: one sender id,
    numbers 0, 1, 2, ... (None without a key)."""
    if key is None:
        return lambda _payload: None
    prefix, sender = key_expr.encode() + _SEP, secrets.randbits(64)
    numbers = itertools.count()  # next() is atomic: publishers may share a signer
    pack = _STAMP.pack

    def attach(payload: bytes) -> bytes:
        stamp = pack(role, sender, next(numbers))
        return hmac.digest(key, prefix + stamp + payload, "sha256")[:TAG_BYTES] + stamp

    return attach


@final
class ReplayWindow:
    """Which (sender id, sequence number) pairs a subscription has let through, per key
    expression (module docstring); thread-safe (Zenoh calls back on its threads)."""

    __slots__ = ("_lock", "_seen")

    def __init__(self) -> None:
        self._seen: dict[tuple[str, int], tuple[int, int]] = {}  # -> (highest, bit mask)
        self._lock = threading.Lock()

    def fresh(self, key_expr: str, stamp: Stamp) -> bool:
        """True, and remembered, the first time `stamp` comes on `key_expr`; False for a
        number seen before or older than `WINDOW` behind the sender's highest."""
        sender, number = (key_expr, stamp.sender), stamp.sequence
        with self._lock:
            state = self._seen.get(sender)
            if state is None:
                if len(self._seen) >= _SENDERS:
                    del self._seen[next(iter(self._seen))]
                self._seen[sender] = (number, 1)
                return True
            highest, mask = state
            if number > highest:
                mask = ((mask << min(number - highest, WINDOW)) | 1) & ((1 << WINDOW) - 1)
                self._seen[sender] = (number, mask)
                return True
            behind = highest - number
            if behind >= WINDOW or (mask >> behind) & 1:
                return False
            self._seen[sender] = (highest, mask | (1 << behind))
            return True


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


@final
class WrongTypes:
    """Messages of a type their handler does not take, per (sender, topic): each pair's
    line (`contract.dispatch.wrong_type_line`, the checker's words) and how many came."""

    def __init__(self) -> None:
        self.seen: dict[tuple[str, str], list[Any]] = {}  # (sender, topic) -> [line, count]

    def note(self, sender: str, topic: str, msg: Any, expected: type, receiver: str
             ) -> Rejected:
        """Count one such message; the `Rejected` to raise (``first`` for a new pair)."""
        entry = self.seen.get((sender, topic))
        if entry is None:
            entry = self.seen[(sender, topic)] = [
                wrong_type_line(sender, topic, msg, expected, receiver), 0]
        entry[1] += 1
        return Rejected(Rejection.WRONG_TYPE, entry[0], first=entry[1] == 1)

    def lines(self) -> tuple[str, ...]:
        """Every pair's line with its count, in the order the pairs first came."""
        return tuple(f"{line} ({count} samples)" for line, count in self.seen.values())


@final
class Admission:
    """The checks one subscription's decoded samples pass before they reach the handler.

    Args:
        expected: the message class the handler declares (None: any registered type).
        receiver: ``node.handler``, named when a message of another type comes.
        topic: the subscription's topic.
        wrong: where messages of another type are noted (None: not noted).
    """

    __slots__ = ("expected", "receiver", "topic", "wrong")

    def __init__(self, expected: type | None, receiver: str = "", topic: str = "",
                 wrong: WrongTypes | None = None) -> None:
        self.expected, self.receiver, self.topic, self.wrong = expected, receiver, topic, wrong

    def __call__(self, msg: Any, sender: str = "") -> None:
        """Raise `Rejected` for a message of the wrong type or with invalid fields."""
        expected = self.expected
        if expected is not None and type(msg) is not expected:
            if self.wrong is not None and sender != OPERATOR_SENDER:
                raise self.wrong.note(sender, self.topic, msg, expected, self.receiver)
            raise Rejected(Rejection.WRONG_TYPE,
                           f"{getattr(type(msg), '__message_type__', type(msg).__name__)} where "
                           f"{expected.__message_type__} is expected")  # type: ignore[attr-defined]
        check_message(msg)
