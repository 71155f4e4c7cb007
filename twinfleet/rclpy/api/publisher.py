"""`rclpy.publisher.Publisher`."""

from __future__ import annotations

from typing import Any


class Publisher:
    """Publishes copies of messages of one type on one topic."""

    def __init__(self, engine: Any, index: int) -> None:
        self._engine, self._index = engine, index
        engine.handles[("publisher", index)] = self
        self._tf_key = f"publisher:{index}"  # how a state names it (twinfleet.rclpy.state)

    def _tf_ref(self) -> tuple[str, int] | None:
        return ("publisher", self._index)

    @property
    def topic_name(self) -> str:
        """The fully qualified topic."""
        return str(self._engine.adapter.resolve(self._engine.publishers[self._index].topic))

    @property
    def msg_type(self) -> type:
        """The message class."""
        return self._engine.publishers[self._index].msg_type

    def publish(self, msg: Any) -> None:
        """Publish a copy of `msg`."""
        self._engine.publish(self._index, msg)

    def get_subscription_count(self) -> int:
        """Not known inside a node under twinfleet: 0."""
        return 0

    def destroy(self) -> None:
        """Accepted; publishers live as long as the node."""
