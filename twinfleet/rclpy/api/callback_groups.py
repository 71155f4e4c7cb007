"""`rclpy.callback_groups`: which callbacks may run while another is running or suspended.

A callback of a `MutuallyExclusiveCallbackGroup` (every node's default group) does not
start while another callback of the group runs, and a coroutine callback suspended at
an `await` keeps its group busy until it finishes, as rclpy's executor does. A
`ReentrantCallbackGroup` never holds anything back.
"""

from __future__ import annotations


class CallbackGroup:
    """Base class of callback groups."""

    exclusive = False

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"


class MutuallyExclusiveCallbackGroup(CallbackGroup):
    """One callback of the group at a time; a suspended coroutine holds the group."""

    exclusive = True


class ReentrantCallbackGroup(CallbackGroup):
    """Callbacks of the group run whenever they are ready."""
