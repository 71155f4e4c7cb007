"""SIGTERM handled as Ctrl-C is, so that every command ends the same way on either.

A search, a statistical estimate or a sweep stops on Ctrl-C at its next step
and prints what it found so far; a supervisor's SIGTERM (a CI timeout, `kill`,
systemd) deserves the same partial summary, where Python's default would end
the process silently. `Interrupts` routes SIGTERM to whatever handles SIGINT at
that moment (a search's own handler, or Python's KeyboardInterrupt) and
remembers which signal came, so the command's "interrupted" exit code 130
becomes 143 (128 + 15) for SIGTERM, as shells report a signal.
"""

from __future__ import annotations

import signal
import threading
from types import FrameType, TracebackType
from typing import Any, final

from twinfleet.runtime.contract.kinds import EXIT_INTERRUPTED, EXIT_TERMINATED


@final
class Interrupts:
    """A context manager (main thread only; elsewhere it does nothing) for one command."""

    def __init__(self) -> None:
        self.terminated = False
        self._previous: Any = None
        self._active = threading.current_thread() is threading.main_thread()

    def __enter__(self) -> Interrupts:
        if self._active:
            self._previous = signal.signal(signal.SIGTERM, self._on_sigterm)
        return self

    def __exit__(self, kind: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        if self._active:
            signal.signal(signal.SIGTERM, self._previous)

    def _on_sigterm(self, signum: int, frame: FrameType | None) -> None:
        self.terminated = True
        handler = signal.getsignal(signal.SIGINT)
        if callable(handler):
            handler(signal.SIGINT, frame)
        else:  # SIG_IGN or SIG_DFL set by someone: stop as Ctrl-C would
            raise KeyboardInterrupt

    def exit_code(self, code: int) -> int:
        """`code`, with 130 (interrupted) made 143 when the signal was SIGTERM."""
        return EXIT_TERMINATED if code == EXIT_INTERRUPTED and self.terminated else code
