"""`run_handler`: the one place where a handler is run, for both drivers."""

from __future__ import annotations

import traceback
from dataclasses import dataclass
from typing import Any

from twinfleet.runtime.contract.context import Context, ContractError, Effect
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
    not complete). A service handler that returns a non-message keeps its effects.
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
    if expects_reply and not is_message(reply):
        return None, HandlerError(node.name, method,
                                  f"service handler returned {reply!r:.60}, not a message")
    return reply, None


def run_handler(node: Node, method: str, ctx: Context, args: tuple[Any, ...] = (),
                *, expects_reply: bool = False) -> HandlerOutcome:
    """Run `node.<method>(ctx, *args)` to completion and collect what it did (see `invoke`)."""
    reply, error = invoke(node, method, ctx, args, expects_reply)
    return HandlerOutcome(reply, tuple(ctx.effects), tuple(ctx.choices), error)
