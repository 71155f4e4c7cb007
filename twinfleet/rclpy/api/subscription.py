"""`rclpy.subscription.Subscription`."""

from __future__ import annotations

from typing import Any


class Subscription:
    """A subscription made in the node's `__init__`."""

    def __init__(self, engine: Any, index: int) -> None:
        self._engine, self._index = engine, index
        engine.handles[("subscription", index)] = self
        self._tf_key = f"subscription:{index}"  # how a state names it (twinfleet.rclpy.state)

    def _tf_ref(self) -> tuple[str, int] | None:
        return ("subscription", self._index)

    @property
    def topic_name(self) -> str:
        """The fully qualified topic."""
        return str(self._engine.adapter.resolve(self._engine.subscriptions[self._index].topic))

    @property
    def callback_group(self) -> Any:
        """The group its callback runs in."""
        return self._engine.groups[self._engine.subscriptions[self._index].group]

    def destroy(self) -> None:
        """Accepted; subscriptions live as long as the node."""
