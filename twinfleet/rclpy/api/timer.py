"""`rclpy.timer`: `Timer` (cancel, reset, is_canceled) and `Rate` (whose sleep is refused)."""

from __future__ import annotations

from typing import Any

from twinfleet.runtime.contract.context import ContractError


class Timer:
    """A periodic timer of the node."""

    def __init__(self, engine: Any, index: int) -> None:
        self._engine, self._index = engine, index
        engine.handles[("timer", index)] = self
        self._tf_key = f"timer:{index}"  # how a state names it (twinfleet.rclpy.state)

    def _tf_ref(self) -> tuple[str, int] | None:
        return ("timer", self._index)

    @property
    def timer_period_ns(self) -> int:
        """The period in nanoseconds."""
        return int(self._engine.timer_slot(self._index).period_ms * 1_000_000)

    def cancel(self) -> None:
        """Stop firing until `reset`."""
        self._engine.cancel_timer(self._index)

    def reset(self) -> None:
        """Fire one period from now, and periodically after."""
        self._engine.reset_timer(self._index)

    def is_canceled(self) -> bool:
        """True after `cancel` (until `reset`)."""
        return bool(self._engine.timer_slot(self._index).canceled)

    def is_ready(self) -> bool:
        """False: a ready timer runs at once under twinfleet."""
        return False

    def destroy(self) -> None:
        """Remove the timer."""
        self._engine.destroy_timer(self._index)


class Rate:
    """`node.create_rate(hz)`: its `sleep` blocks, so it is refused inside a callback."""

    def __init__(self, engine: Any, frequency: float) -> None:
        self._engine, self.frequency = engine, frequency
        self._index = sum(1 for kind, _ in engine.handles if kind == "rate")
        engine.handles[("rate", self._index)] = self

    def _tf_ref(self) -> tuple[str, int]:
        return ("rate", self._index)

    def sleep(self) -> None:
        """Refused: sleeping blocks rclpy's executor."""
        raise ContractError(f"{self._engine.name}: Rate.sleep() blocks inside a callback",
                            "use a timer (node.create_timer(period, callback)) instead")

    def destroy(self) -> None:
        """Accepted."""
