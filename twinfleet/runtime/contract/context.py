"""The context a handler receives: its only way to act on the world.

One `Context` class serves both drivers. A handler's effects are recorded as
values (`Publish`, `Call`, `After`, `Fail`, `Log`, `Defer`, `Reply`) in `ctx.effects`; the live
host performs them over Zenoh, the checker turns them into pending events.
The only inputs that differ between the modes are the time stamped on the
dispatch (`now_ms`) and the `Chooser` that answers `ctx.choose`.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol, TypeVar

from twinfleet.runtime.contract.messages import is_message

if TYPE_CHECKING:
    from twinfleet.runtime.contract.node import Node

T = TypeVar("T")

DEFAULT_CALL_TIMEOUT_MS = 2000


class ContractError(TypeError):
    """A handler used the context in a way the node contract forbids; `fix` says how to
    mend it when the misuse says which (else the checker names the usual fix)."""

    def __init__(self, text: str, fix: str = "") -> None:
        super().__init__(text)
        self.fix = fix


FIX_MESSAGE = ('register the class with @message("pkg/Name") (a frozen dataclass): only '
               "registered messages can be sent, since both ends must decode them")


class Chooser(Protocol):
    """Answers `ctx.choose`: live from a seeded RNG, in the checker by enumeration."""

    def choose(self, n: int) -> int:
        """Return an index in range(n)."""
        ...


class FirstChooser:
    """Always picks option 0 (tests, and node start-up outside any driver)."""

    def choose(self, n: int) -> int:
        return 0


@dataclass(frozen=True, slots=True)
class Publish:
    """Publish `msg` on the fully qualified `topic`."""

    topic: str
    msg: Any


@dataclass(frozen=True, slots=True)
class Call:
    """Call service `service` with `request`; the reply or a CallError goes to `reply_to`."""

    service: str
    request: Any
    reply_to: str
    timeout_ms: int


@dataclass(frozen=True, slots=True)
class After:
    """Run this node's method `handler` with `args` after `delay_ms`."""

    delay_ms: int
    handler: str
    args: tuple[Hashable, ...]


@dataclass(frozen=True, slots=True)
class Fail:
    """The handler reports a violation of what the node expects."""

    reason: str


@dataclass(frozen=True, slots=True)
class Log:
    """A structured log line."""

    event: str
    fields: tuple[tuple[str, Any], ...]


@dataclass(frozen=True, slots=True)
class ReplyToken:
    """A request whose reply was deferred (`Context.defer_reply`): which call it answers.

    It names the call as both drivers see it (the service, the calling node, the caller's
    reply handler and the request), so it can live in the node's state: the checker's
    states include it and a live node's state equals the model's. Two tokens are equal
    only for calls the caller cannot tell apart (same handler, same request).
    """

    service: str
    caller: str
    reply_to: str
    request: Any


@dataclass(frozen=True, slots=True)
class Defer:
    """The service handler that ran will not reply now: `Reply` with `token` answers later."""

    token: ReplyToken


@dataclass(frozen=True, slots=True)
class Reply:
    """Answer the deferred request `token` with `msg`."""

    token: ReplyToken
    msg: Any


Effect = Publish | Call | After | Fail | Log | Defer | Reply


_FIRST = FirstChooser()


class Context:
    """What a running handler may read (`now`, `choose`) and do (everything else).

    A plain slotted class (one is built per dispatched event, on the live hot path).

    Args:
        node: the node whose handler runs.
        now_ms: the time the handler sees.
        chooser: answers `choose` (default: always option 0).

    A driver that runs a service handler sets `serving` to the request's `ReplyToken`
    first (`defer_reply` hands it out); it is None for every other handler.
    """

    __slots__ = ("node", "now_ms", "chooser", "effects", "choices", "serving")

    def __init__(self, node: Node, now_ms: int, chooser: Chooser | None = None) -> None:
        self.node = node
        self.now_ms = now_ms
        self.chooser: Chooser = _FIRST if chooser is None else chooser
        self.effects: list[Effect] = []
        self.choices: list[int] = []
        self.serving: ReplyToken | None = None

    def __repr__(self) -> str:
        return (f"Context(node={self.node.name!r}, now_ms={self.now_ms}, "
                f"effects={self.effects!r}, choices={self.choices!r})")

    def now(self) -> int:
        """Milliseconds since the fleet's common start (logical time in the checker)."""
        return self.now_ms

    def publish(self, topic: str, msg: Any) -> None:
        """Publish a message; relative topics resolve in the node's namespace."""
        if not hasattr(type(msg), "__message_type__"):  # is_message, inlined: a hot path
            raise ContractError(f"{self.node.name}: publish({topic!r}) needs a message, got "
                                f"{msg!r:.60}", FIX_MESSAGE)
        self.effects.append(Publish(self.node.resolve(topic), msg))

    def call(
        self,
        service: str,
        request: Any,
        on_reply: Callable[..., Any],
        *,
        timeout_ms: int = DEFAULT_CALL_TIMEOUT_MS,
    ) -> None:
        """Call a service; `on_reply(ctx, reply)` later gets the reply or a CallError."""
        if not is_message(request):
            raise ContractError(f"{self.node.name}: call({service!r}) needs a message request, "
                                f"got {request!r:.60}", FIX_MESSAGE)
        method = self._own_method(on_reply, "call")
        self.effects.append(Call(self.node.resolve(service), request, method, int(timeout_ms)))

    def after(self, delay_ms: int, handler: Callable[..., Any], *args: Hashable) -> None:
        """Run `handler(ctx, *args)` — a method of this node — after `delay_ms` ms."""
        if not isinstance(delay_ms, int) or delay_ms < 0:
            raise ContractError(f"{self.node.name}: after() needs an integer delay >= 0, got {delay_ms!r}")
        for arg in args:
            try:
                hash(arg)  # pending timers are hashed into checker states
            except TypeError:
                raise ContractError(f"{self.node.name}: after() arguments must be hashable, got "
                                    f"{arg!r:.60} ({type(arg).__name__}); pass a tuple instead "
                                    "of a list") from None
        method = self._own_method(handler, "after")
        self.effects.append(After(delay_ms, method, tuple(args)))

    def choose(self, options: Sequence[T]) -> T:
        """Pick one option: at random live, every option in turn in the checker."""
        if len(options) == 0:
            raise ContractError(f"{self.node.name}: choose() needs at least one option")
        index = self.chooser.choose(len(options)) if len(options) > 1 else 0
        self.choices.append(index)
        return options[index]

    def fail(self, reason: str) -> None:
        """Report a violation (counted live, a property violation in the checker)."""
        self.effects.append(Fail(str(reason)))

    def log(self, event: str, **fields: Any) -> None:
        """Record a structured log line."""
        self.effects.append(Log(event, tuple(sorted(fields.items()))))

    def defer_reply(self) -> ReplyToken:
        """Inside a `@service` handler: reply later, with `reply(token, response)` from any
        handler of this node (the handler then returns None). Keep the token in
        `self.state`; the caller waits for the reply (or its call's timeout)."""
        token = self.serving
        if token is None:
            raise ContractError(f"{self.node.name}: defer_reply() outside a @service handler",
                                "call defer_reply() in the service handler whose request "
                                "is to be answered later")
        if Defer(token) not in self.effects:
            self.effects.append(Defer(token))
        return token

    def reply(self, token: ReplyToken, response: Any) -> None:
        """Answer the request whose reply `defer_reply` deferred (once per token)."""
        if not isinstance(token, ReplyToken):
            raise ContractError(f"{self.node.name}: reply() needs the token defer_reply() "
                                f"gave, got {token!r:.60}")
        if not is_message(response):
            raise ContractError(f"{self.node.name}: reply() to {token.service} needs a message "
                                f"response, got {response!r:.60}", FIX_MESSAGE)
        self.effects.append(Reply(token, response))

    def _own_method(self, fn: Callable[..., Any], what: str) -> str:
        owner = getattr(fn, "__self__", None)
        name = getattr(fn, "__name__", None)
        if owner is not self.node or name is None or getattr(type(owner), name, None) is None:
            raise ContractError(
                f"{self.node.name}: {what}() needs a method of the node itself "
                f"(e.g. self.on_reply), got {fn!r:.60}; lambdas and other objects cannot be "
                "stored in pending events"
            )
        return name
