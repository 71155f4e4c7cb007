"""`run_handler`: the one place where a handler is run, for both drivers; what a handler
declares it takes, and the line both drivers give when a message is not that."""

from __future__ import annotations

import inspect
import traceback
import typing
from dataclasses import dataclass
from typing import Any

from twinfleet.runtime.contract.context import Context, ContractError, Defer, Effect
from twinfleet.runtime.contract.messages import is_message
from twinfleet.runtime.contract.node import Node


@dataclass(frozen=True, slots=True)
class HandlerError:
    """An exception raised by a handler (or a bad return value of a service)."""

    node: str
    handler: str
    message: str
    traceback: str = ""
    contract: bool = False  # a `ContractError`: the handler misused `ctx`
    fix: str = ""  # how to mend that misuse, when the `ContractError` says

    def __str__(self) -> str:
        return f"{self.node}.{self.handler}: {self.message}"


@dataclass(frozen=True, slots=True)
class HandlerOutcome:
    """What a handler did: its reply (services), effects, choices made, error if any."""

    reply: Any
    effects: tuple[Effect, ...]
    choices: tuple[int, ...]
    error: HandlerError | None


def invoke(node: Node, method: str, ctx: Context, args: tuple[Any, ...] = (),
           expects_reply: bool = False) -> tuple[Any, HandlerError | None]:
    """Run `node.<method>(ctx, *args)` to completion: the handler semantics, for both drivers.

    Returns ``(reply, error)``; the effects stay in ``ctx.effects``. Exceptions never
    escape: they come back as the error, with ``ctx.effects`` emptied (the handler did
    not complete). A service handler that returns a non-message keeps its effects; one
    that deferred its reply (`Context.defer_reply`) must return None, and its reply is None.
    """
    fn = getattr(node, method, None)
    if fn is None:
        return None, HandlerError(node.name, method, f"node has no handler {method!r}")
    try:
        reply = fn(ctx, *args)
    except Exception as exc:
        ctx.effects.clear()
        return None, HandlerError(node.name, method, f"{type(exc).__name__}: {exc}",
                                  traceback.format_exc(limit=8), isinstance(exc, ContractError),
                                  exc.fix if isinstance(exc, ContractError) else "")
    if expects_reply and deferred(ctx):
        if reply is None:
            return None, None
        ctx.effects.clear()
        return None, HandlerError(node.name, method, f"service handler returned {reply!r:.60} "
                                  "after defer_reply(); send it with ctx.reply(token, ...)",
                                  contract=True, fix="return None from a handler that deferred "
                                  "its reply")
    if expects_reply and not is_message(reply):
        return None, HandlerError(node.name, method,
                                  f"service handler returned {reply!r:.60}, not a message")
    return reply, None


def deferred(ctx: Context) -> bool:
    """True if the service handler that ran in `ctx` deferred its reply."""
    return ctx.serving is not None and any(type(e) is Defer for e in ctx.effects)


def run_handler(node: Node, method: str, ctx: Context, args: tuple[Any, ...] = (),
                *, expects_reply: bool = False) -> HandlerOutcome:
    """Run `node.<method>(ctx, *args)` to completion and collect what it did (see `invoke`)."""
    reply, error = invoke(node, method, ctx, args, expects_reply)
    return HandlerOutcome(reply, tuple(ctx.effects), tuple(ctx.choices), error)


def declared_message_type(node: Any, method: str) -> type | None:
    """The message class a handler ``fn(self, ctx, msg: Cls)`` of `node` (an instance or
    its class) declares for its message, or None (no annotation, or not a message class)."""
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


def wrong_type_line(sender: str, name: str, sent: object, expected: type, receiver: str,
                    *, call: bool = False) -> str:
    """The one line both drivers give for a message whose type is not the one its
    receiving handler declares: sender, topic or service, both types and the handler."""
    sent_name = getattr(sent if isinstance(sent, type) else type(sent), "__message_type__",
                        type(sent).__name__)
    expected_name = getattr(expected, "__message_type__", expected.__name__)
    how = f"called {name} with" if call else f"published on {name}"
    return (f"wrong message type: {sender} {how} {sent_name}, but {receiver} takes "
            f"{expected_name}; fix: send {expected_name} or change the handler's annotation")
