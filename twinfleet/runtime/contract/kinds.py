"""The contract's vocabulary: what kind of event a handler runs for, what kind of failure,
and how a check or a run came out.

One `EventKind` names an event the same way in the node contract, both drivers
(the live node core and the checker), the live event log, checker traces and
`twinfleet.agreement`. One `FailureKind` names why a handler run failed. One
`Status` names a verdict for the checker, the live verdict and the experiment
table. All are `StrEnum`s, so their values are the strings written to logs,
traces and JSON. The exit codes of every command are here too: the checker's
results and the CLI's commands give the same answers the same numbers
(`Status.exit_code`).
"""

from __future__ import annotations

from enum import StrEnum, unique
from typing import Final

# One table of exit codes for every command (README and `twinfleet --help` list it).
EXIT_OK: Final = 0  # ok; every property holds; the run passed
EXIT_FAILED: Final = 1  # a property is violated; the run FAILED
EXIT_BAD_INPUT: Final = 2  # bad input, or no answer
EXIT_INCONCLUSIVE: Final = 3  # the run cannot back a verdict (it says why)
EXIT_CONTRACT_BREACH: Final = 4  # a user's node broke the node contract
EXIT_INTERRUPTED: Final = 130  # Ctrl-C (SIGINT), as shells report 128 + the signal
EXIT_TERMINATED: Final = 143  # SIGTERM (128 + 15), after the same partial summary as Ctrl-C


@unique
class EventKind(StrEnum):
    """The kind of an event: what made a handler run."""

    START = "start"  # @on_start, once when the node starts
    DELIVERY = "delivery"  # a published message reaching an @subscribe handler
    REQUEST = "request"  # a service request reaching an @service handler
    REPLY = "reply"  # a service's answer reaching the caller's reply handler
    TIMEOUT = "timeout"  # a call that got no answer in time: the reply handler gets a CallError
    TIMER = "timer"  # a one-shot `ctx.after` timer firing
    PERIODIC = "periodic"  # an @every tick
    CRASH = "crash"  # a node crashing (a checker fault; live, the process dies)
    LIVELINESS = "liveliness"  # a node appearing or disappearing, to /_liveliness subscribers
    DROP = "drop"  # a waiting delivery dropped by KEEP_LAST (a label of the checker, never run)

    @property
    def is_message(self) -> bool:
        """True for events another node sent: they keep per-sender order (Rule 3 of
        `checker.semantics`; docs/design.md §3)."""
        return self in _MESSAGES


_MESSAGES = frozenset({EventKind.DELIVERY, EventKind.REQUEST, EventKind.REPLY})


@unique
class FailureKind(StrEnum):
    """Why a handler run counts as failed."""

    HANDLER = "handler failure"  # ctx.fail(...) or an exception in the handler
    STATE_OUTSIDE = "state outside self.state"  # a handler changed another attribute
    DEADLINE = "deadline miss"  # a message handled after its deadline
    NONDETERMINISM = "nondeterminism"  # the same handler run twice did different things
    CHOICE_MISMATCH = "choice mismatch"  # a forced ctx.choose answer this run does not offer
    CONTRACT = "contract misuse"  # a lambda as a timer, state that cannot be encoded, a clock read


@unique
class Status(StrEnum):
    """How a property check or a live run came out; the value is the word printed and
    written to JSON. The checker answers HOLDS, VIOLATED, UNKNOWN or BREACH; a live run
    HOLDS, VIOLATED, ERROR, INCONCLUSIVE or INTERRUPTED."""

    HOLDS = "holds"  # every property holds (the checker: in every interleaving)
    VIOLATED = "violated"  # a property is violated (or, live, a node process failed)
    UNKNOWN = "unknown"  # the checker stopped before a verdict (a limit, Ctrl-C)
    BREACH = "contract breach"  # a node breaks the node contract: no verdict
    ERROR = "error"  # a property raised: a scenario mistake
    INCONCLUSIVE = "inconclusive"  # the live run cannot back a verdict (it says why)
    INTERRUPTED = "interrupted"  # the live run was stopped (a signal) before a verdict

    @property
    def exit_code(self) -> int:
        """The command's exit code for this outcome."""
        return _EXIT_CODES[self]


_EXIT_CODES: Final = {
    Status.HOLDS: EXIT_OK, Status.VIOLATED: EXIT_FAILED, Status.UNKNOWN: EXIT_BAD_INPUT,
    Status.BREACH: EXIT_CONTRACT_BREACH, Status.ERROR: EXIT_BAD_INPUT,
    Status.INCONCLUSIVE: EXIT_INCONCLUSIVE, Status.INTERRUPTED: EXIT_INTERRUPTED,
}
