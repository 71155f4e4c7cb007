"""The `rclpy` that node code loaded by twinfleet imports (twinfleet.rclpy.loader).

`init`, `shutdown`, `ok` and friends keep rclpy's names and meaning for a program's
`main()`; spinning is twinfleet's job (the live host or the checker runs the node's
callbacks), so `spin` inside a callback is the blocking idiom refused with rclpy's
advice, and outside one it says how twinfleet runs nodes.
"""

from __future__ import annotations

from typing import Any

from twinfleet.rclpy.api.executors import refuse_spin

_STATE = {"ok": False}


def init(*, args: Any = None, context: Any = None, domain_id: int | None = None,
         signal_handler_options: Any = None) -> None:
    """Start rclpy (a no-op beyond `ok()` turning True)."""
    _STATE["ok"] = True


def shutdown(*, context: Any = None, uninstall_handlers: bool | None = None) -> None:
    """Stop rclpy."""
    _STATE["ok"] = False


def try_shutdown(*, context: Any = None, uninstall_handlers: bool | None = None) -> None:
    """Stop rclpy if it runs."""
    _STATE["ok"] = False


def ok(*, context: Any = None) -> bool:
    """True between `init` and `shutdown`, and always inside a node twinfleet runs."""
    from twinfleet.rclpy.current import active_engine
    return _STATE["ok"] or active_engine() is not None


def create_node(node_name: str, **kwargs: Any) -> Any:
    """A plain `Node`."""
    from twinfleet.rclpy.api.node import Node
    return Node(node_name, **kwargs)


def spin(node: Any, executor: Any = None) -> None:
    """See `twinfleet.rclpy.api.executors.refuse_spin`."""
    refuse_spin("rclpy.spin()")


def spin_once(node: Any, *, executor: Any = None, timeout_sec: float | None = None) -> None:
    """See `refuse_spin`."""
    refuse_spin("rclpy.spin_once()")


def spin_until_future_complete(node: Any, future: Any, executor: Any = None,
                               timeout_sec: float | None = None) -> None:
    """See `refuse_spin`."""
    refuse_spin("rclpy.spin_until_future_complete()")


def get_global_executor() -> Any:
    """A single-threaded executor."""
    from twinfleet.rclpy.api.executors import SingleThreadedExecutor
    return SingleThreadedExecutor()


# As real rclpy's package does, make its modules attributes of `rclpy` (`rclpy.qos.QoSProfile`
# after a bare `import rclpy`).
from twinfleet.rclpy.api import (  # noqa: E402
    callback_groups,
    client,
    clock,
    duration,
    exceptions,
    executors,
    logging,
    node,
    parameter,
    publisher,
    qos,
    service,
    subscription,
    task,
    time,
    timer,
)

__all__ = ["callback_groups", "client", "clock", "create_node", "duration", "exceptions",
           "executors", "get_global_executor", "init", "logging", "node", "ok", "parameter",
           "publisher", "qos", "service", "shutdown", "spin", "spin_once",
           "spin_until_future_complete", "subscription", "task", "time", "timer", "try_shutdown"]
