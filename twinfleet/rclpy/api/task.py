"""`rclpy.task`: `Future` and `Task`.

A future completes once; its done callbacks then run as new tasks of the executor
(outside every callback group), and every coroutine awaiting it resumes. Under
twinfleet both happen within the step that completes the future: the reply of a
`call_async` is one event of the node, and what it sets off runs in that event.
`await future` suspends the coroutine until then; awaiting anything but an rclpy
future is refused, since nothing else can complete inside a node.
"""

from __future__ import annotations

from collections.abc import Callable, Generator
from typing import Any

from twinfleet.rclpy.api.exceptions import NotSupportedError

_PENDING, _FINISHED, _CANCELLED = 0, 1, 2


class Future:
    """The result of an operation that completes later (`Client.call_async`)."""

    def __init__(self, *, executor: Any = None) -> None:
        self._state = _PENDING
        self._result: Any = None
        self._exception: BaseException | None = None
        self._callbacks: list[Callable[[Future], Any]] = []
        self._engine: Any = None  # the node engine told when the future completes

    def __repr__(self) -> str:
        state = ("pending", "finished", "cancelled")[self._state]
        return f"<Future {state}>"

    def __await__(self) -> Generator[Future, Any, Any]:
        if self._state == _PENDING:
            fed = yield self  # the engine suspends the coroutine here (twinfleet.rclpy.tasks)
            if self._state == _PENDING:  # a re-executed await: the engine feeds the result
                self._result, self._state = fed, _FINISHED
        return self.result()

    def done(self) -> bool:
        """True once a result, an exception or a cancellation is set."""
        return self._state != _PENDING

    def cancelled(self) -> bool:
        """True if the future was cancelled."""
        return self._state == _CANCELLED

    def cancel(self) -> None:
        """Cancel a pending future; its done callbacks run."""
        if self._state == _PENDING:
            self._state = _CANCELLED
            self._completed()

    def result(self) -> Any:
        """The result (None while pending); raises the exception if one was set."""
        if self._exception is not None:
            raise self._exception
        return self._result

    def exception(self) -> BaseException | None:
        """The exception set, if any."""
        return self._exception

    def set_result(self, result: Any) -> None:
        """Complete the future with `result`."""
        self._result, self._state = result, _FINISHED
        self._completed()

    def set_exception(self, exception: BaseException) -> None:
        """Complete the future with an exception."""
        self._exception, self._state = exception, _FINISHED
        self._completed()

    def add_done_callback(self, callback: Callable[[Future], Any]) -> None:
        """Run `callback(future)` once the future is done (at once if it already is)."""
        if self.done():
            callback(self)
        else:
            self._callbacks.append(callback)

    def remove_done_callback(self, callback: Callable[[Future], Any]) -> bool:
        """Forget a done callback; True if it was there."""
        try:
            self._callbacks.remove(callback)
        except ValueError:
            return False
        return True

    def _completed(self) -> None:
        from twinfleet.rclpy.current import active_engine
        engine = self._engine or active_engine()
        callbacks, self._callbacks = self._callbacks, []
        if engine is None:
            for callback in callbacks:
                callback(self)
        else:
            engine.future_done(self, callbacks)


class Task(Future):
    """A coroutine run by the executor; not created by node code under twinfleet."""

    def __init__(self, handler: Callable[..., Any], args: Any = None, kwargs: Any = None,
                 executor: Any = None) -> None:
        raise NotSupportedError("rclpy.task.Task: create work with timers, subscriptions and "
                                "futures; executor.create_task is not supported by twinfleet")
