"""The one-line error every command may raise, and its prefix.

`CommandError` is how a command says "bad input or no answer": `twinfleet.cli`
prints its text as one line on stderr and exits with its code (2). Kept apart
from `connection` (which re-exports both) so that the command line imports
neither the fleet's credentials nor what they import to report an error.
"""

from __future__ import annotations

import argparse

from twinfleet.runtime.contract.kinds import EXIT_BAD_INPUT


class CommandError(Exception):
    """A command cannot do what was asked; its text is one line naming what and where."""

    def __init__(self, text: str, code: int = EXIT_BAD_INPUT) -> None:
        super().__init__(text)
        self.code = code


def error_prefix(args: argparse.Namespace | None) -> str:
    """The prefix of every command's one-line errors: ``twinfleet topic echo:``, say."""
    words = [getattr(args, name, None) for name in ("command", "action")] if args else []
    return " ".join(["twinfleet", *(w for w in words if isinstance(w, str))]) + ":"
