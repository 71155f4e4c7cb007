"""`rclpy.client.Client`: `call_async` returns a `Future`; blocking `call` is refused."""

from __future__ import annotations

from typing import Any

from twinfleet.rclpy.api.task import Future
from twinfleet.runtime.contract.context import ContractError


class Client:
    """A service client made in the node's `__init__`."""

    def __init__(self, engine: Any, index: int) -> None:
        self._engine, self._index = engine, index
        engine.handles[("client", index)] = self
        self._tf_key = f"client:{index}"  # how a state names it (twinfleet.rclpy.state)

    def _tf_ref(self) -> tuple[str, int] | None:
        return ("client", self._index)

    @property
    def srv_name(self) -> str:
        """The fully qualified service name."""
        return str(self._engine.adapter.resolve(self._engine.clients[self._index].name))

    @property
    def srv_type(self) -> type:
        """The service class."""
        return self._engine.clients[self._index].srv_type

    def call_async(self, request: Any) -> Future:
        """Send `request`; the future completes with the response when it arrives."""
        future = Future()
        self._engine.call(self._index, request, future)
        return future

    def call(self, request: Any, timeout_sec: float | None = None) -> Any:
        """Refused: a blocking call inside a callback deadlocks rclpy's executor."""
        raise ContractError(
            f"{self._engine.name}: Client.call({self.srv_name}) blocks inside a callback",
            "use client.call_async(request) and add_done_callback, or await it in a "
            "callback of a ReentrantCallbackGroup")

    def service_is_ready(self) -> bool:
        """True: the scenario's servers are there from the start (checked at load)."""
        return True

    def wait_for_service(self, timeout_sec: float | None = None) -> bool:
        """True at once (see `service_is_ready`); never blocks."""
        return True

    def destroy(self) -> None:
        """Accepted; clients live as long as the node."""
