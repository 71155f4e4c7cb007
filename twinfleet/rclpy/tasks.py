"""Coroutine callbacks: run to the first pending `await`, kept as values, resumed by
re-execution.

A coroutine cannot be copied, and the checker must resume one suspended callback in
many successor states. So a suspended callback is kept as what made it (`Suspended`:
the callback, its arguments, the state the node was in when it began, the results of
the awaits it passed and the times its steps read) and resumed by running it again:
the node's attributes and the engine's state are set back to the start state, the
callback runs with every effect discarded, each `await` is fed its recorded result,
and when it reaches the await that is now answered, the node's current attributes
and engine state are put back and the coroutine goes on with the new result, for real.
Node code is deterministic (the contract's probes check it), so the re-run takes the
same path and rebuilds the coroutine's local variables.

What this assumes, beside determinism: a local variable that refers to a mutable
attribute of the node (``items = self.items``) across an `await` refers, after a
resume, to the copy of the start state, not to the node's attribute (read attributes
through `self` after an await; docs/rclpy.md).
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Coroutine
from typing import Any

from twinfleet.rclpy import state as state_codec
from twinfleet.rclpy import wire
from twinfleet.rclpy.api.task import Future
from twinfleet.rclpy.entities import ServiceEntry, Suspended
from twinfleet.runtime.contract.context import Context, ContractError, ReplyToken

Engine = Any  # twinfleet.rclpy.engine.Engine (which imports this module)


_ASYNC: dict[Any, bool] = {}


def _is_async(callback: Callable[..., Any]) -> bool:
    """True for a coroutine function (a bound method, a partial of one), cached per code
    object (lambdas and closures are new function objects each time)."""
    fn = getattr(callback, "__func__", None) or getattr(callback, "func", None) or callback
    key = getattr(fn, "__code__", None)
    if key is None:
        return inspect.iscoroutinefunction(fn)
    known = _ASYNC.get(key)
    if known is None:
        known = _ASYNC[key] = inspect.iscoroutinefunction(fn)
    return known


#: What `Tasks.serve` returns for a request whose reply comes later (`Context.reply`).
DEFERRED: Any = object()


class Tasks:
    """The coroutine part of one node's engine."""

    def __init__(self, engine: Engine) -> None:
        self.engine = engine

    def start(self, callback: Callable[..., Any], args: tuple[Any, ...], group: int | None) -> None:
        """Run a ready callback; a coroutine callback may end up suspended."""
        record, result = self._begin(callback, args, group, None)
        if record is not None:
            self.step(result, record, None)

    def _begin(self, callback: Callable[..., Any], args: tuple[Any, ...], group: int | None,
               reply: ReplyToken | None) -> tuple[Suspended | None, Any]:
        """Call `callback(*args)`: (its task's record, the coroutine) for a coroutine callback
        (recorded before it runs: a resume re-runs it from that state), else (None, its
        result)."""
        if _is_async(callback):
            record = self._record(callback, args, group, reply)
            return record, callback(*args)
        result = callback(*args)
        if inspect.iscoroutine(result):  # e.g. a lambda returning a coroutine: not run yet
            return self._record(callback, args, group, reply), result
        return None, result

    def _record(self, callback: Callable[..., Any], args: tuple[Any, ...], group: int | None,
                reply: ReplyToken | None) -> Suspended:
        engine = self.engine
        return Suspended(callback, state_codec.encode_args(engine, args), group,
                         state_codec.snapshot_state(engine), reply=reply)

    def step(self, coro: Coroutine[Any, Any, Any], record: Suspended, value: Any) -> None:
        """Run `coro` from its current await (fed `value`) to its end or its next await; a
        service callback's end answers its request."""
        done, got = self._send(coro, value)
        if not done:
            self._suspend(record, got)
        elif record.reply is not None:
            self._answer(record.reply, got)

    def _send(self, coro: Coroutine[Any, Any, Any], value: Any) -> tuple[bool, Any]:
        """One step of `coro`: (True, its return value) at its end, else (False, what it
        awaits)."""
        self.engine.clock_read = False
        try:
            return False, coro.send(value)
        except StopIteration as stop:
            return True, stop.value

    def _answer(self, token: Any, response: Any) -> None:
        self.engine.ctx.reply(token, wire.freeze(response))

    def _suspend(self, record: Suspended, awaited: Any) -> None:
        """Keep `record` as a suspended task awaiting `awaited`."""
        engine = self.engine
        record.clocks.append(engine.ctx.now() if engine.clock_read and engine.ctx else None)
        self._check_awaitable(awaited, record)
        record.awaiting = awaited
        engine.dyn.tasks.append(record)

    def _check_awaitable(self, awaited: Any, record: Suspended) -> None:
        if not isinstance(awaited, Future):
            name = getattr(record.callback, "__qualname__", repr(record.callback))
            raise ContractError(
                f"{self.engine.name}: callback {name} awaited {awaited!r:.60}, not an rclpy "
                "future", "await only futures of rclpy (client.call_async(...)); asyncio and "
                "other event loops do not run inside a node")

    def resume_awaiting(self, future: Any) -> None:
        """Resume every coroutine awaiting `future` (just completed)."""
        engine = self.engine
        while True:
            waiting = next((t for t in engine.dyn.tasks if t.awaiting is future), None)
            if waiting is None:
                return
            engine.dyn.tasks.remove(waiting)
            value = future.result()
            coro = self.rebuild(waiting)
            waiting.results.append(value)
            self.step(coro, waiting, value)

    def rebuild(self, record: Suspended) -> Coroutine[Any, Any, Any]:
        """The coroutine of `record`, run again up to its last await (module docstring)."""
        engine = self.engine
        node = engine.node
        saved_attrs, saved_dyn, saved_ctx = node.__dict__, engine.dyn, engine.ctx
        saved_clock = engine.clock_read
        start = state_codec.restore_state(record.start)
        scratch = Context(engine.adapter, 0)
        try:
            state_codec.apply_state(engine, start, fresh_dict=True)
            engine.ctx = scratch
            args = state_codec.decode_args(engine, record.args)
            coro = record.callback(*args)
            value: Any = None
            for i, clock in enumerate(record.clocks):
                scratch.now_ms = 0 if clock is None else clock
                awaited = coro.send(value)
                if i < len(record.results):
                    value = record.results[i]
                _ = awaited
        except StopIteration:
            raise ContractError(
                f"{engine.name}: re-running a suspended callback from its start state took "
                "another path", "a callback must depend only on the node's attributes, its "
                "arguments and what its awaits return") from None
        finally:
            node.__dict__ = saved_attrs
            engine.dyn, engine.ctx, engine.clock_read = saved_dyn, saved_ctx, saved_clock
        return coro

    def serve(self, entry: ServiceEntry, request: Any, token: ReplyToken | None) -> Any:
        """Run a service callback on `request`: its response, or `DEFERRED` when it answers
        later (a coroutine that suspended: its end replies; or `token`, a request that
        waited for its group, whose reply was deferred when it came, is answered now)."""
        engine = self.engine
        response = getattr(entry.srv_type, "Response")()  # noqa: B009  (a generated class)
        record, result = self._begin(entry.callback, (request, response), entry.group, token)
        if record is not None:
            done, result = self._send(result, None)
            if not done:
                if record.reply is None:
                    record.reply = engine.ctx.defer_reply()
                self._suspend(record, result)
                return DEFERRED
        if token is None:
            return result
        self._answer(token, result)
        return DEFERRED
