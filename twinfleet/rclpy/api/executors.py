"""`rclpy.executors`: the executor classes a `main()` names. Under twinfleet the node's
callbacks are run by the live host or the checker, never by an executor object, so
these only record the nodes added; spinning from inside a callback is the blocking
idiom refused with rclpy's advice."""

from __future__ import annotations

from typing import Any

from twinfleet.rclpy.api.exceptions import NotSupportedError
from twinfleet.rclpy.current import active_engine
from twinfleet.runtime.contract.context import ContractError


class ExternalShutdownException(Exception):
    """rclpy was shut down from outside while spinning."""


class ShutdownException(Exception):
    """The executor was shut down."""


class TimeoutException(Exception):
    """A wait timed out."""


def refuse_spin(what: str) -> None:
    """A spin inside a callback blocks the executor that runs it: the contract breach;
    outside one (a program's own `main()`), say how twinfleet runs nodes."""
    engine = active_engine()
    if engine is not None:
        raise ContractError(f"{engine.name}: {what} inside a callback blocks the executor",
                            "use client.call_async(...) with add_done_callback, or await the "
                            "future in a callback of a ReentrantCallbackGroup")
    raise NotSupportedError(f"{what}: twinfleet runs rclpy nodes itself; name the Node class "
                            "in a scenario (class: module:Class) and use twinfleet launch or "
                            "check")


class Executor:
    """Base executor."""

    def __init__(self, *, context: Any = None) -> None:
        self._nodes: list[Any] = []

    def add_node(self, node: Any) -> bool:
        """Remember a node."""
        if node not in self._nodes:
            self._nodes.append(node)
        return True

    def remove_node(self, node: Any) -> None:
        """Forget a node."""
        if node in self._nodes:
            self._nodes.remove(node)

    def get_nodes(self) -> list[Any]:
        """The nodes added."""
        return list(self._nodes)

    def spin(self) -> None:
        """See `refuse_spin`."""
        refuse_spin("executor.spin()")

    def spin_once(self, timeout_sec: float | None = None) -> None:
        """See `refuse_spin`."""
        refuse_spin("executor.spin_once()")

    def spin_until_future_complete(self, future: Any, timeout_sec: float | None = None) -> None:
        """See `refuse_spin`."""
        refuse_spin("spin_until_future_complete()")

    def shutdown(self, timeout_sec: float | None = None) -> bool:
        """Accepted."""
        return True


class SingleThreadedExecutor(Executor):
    """rclpy's single-threaded executor."""


class MultiThreadedExecutor(Executor):
    """rclpy's multi-threaded executor: callbacks of different groups may overlap; here
    they interleave at awaits, and the checker explores every order of ready ones."""

    def __init__(self, num_threads: int | None = None, *, context: Any = None) -> None:
        super().__init__(context=context)
        self.num_threads = num_threads
