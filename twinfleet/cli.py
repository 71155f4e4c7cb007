"""The `twinfleet` command line, assembled from the commands each layer registers.

    twinfleet launch|topic|service|node|view|record|play|export   (twinfleet.runtime.commands)
    twinfleet render                                              (twinfleet.nodes.commands)
    twinfleet check                                               (twinfleet.checker.commands)
    twinfleet replay|validate|experiment                          (twinfleet.agreement.commands)

This module sits above every layer; each layer's `register(subparsers)` adds
its own commands and imports its engines only when a command runs.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from twinfleet.agreement import commands as agreement_commands
from twinfleet.checker import commands as checker_commands
from twinfleet.nodes import commands as nodes_commands
from twinfleet.runtime import commands as runtime_commands

DESCRIPTION = ("twinfleet: run a robot fleet as separate processes over Zenoh, and check the same "
               "node code exhaustively. Every command has --help.")


def build_parser() -> argparse.ArgumentParser:
    """The full argument parser."""
    parser = argparse.ArgumentParser(prog="twinfleet", description=DESCRIPTION)
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    runtime_commands.register(sub)
    nodes_commands.register(sub)
    checker_commands.register(sub)
    agreement_commands.register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Console script `twinfleet`."""
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
