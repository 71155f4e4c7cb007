"""The `twinfleet` command: the parser and `main` (the package docstring lists the commands).

This module sits above every layer; each layer's `register(subparsers)` adds
its own commands and imports its engines only when a command runs.

Errors are one line. A command reports bad input or no answer by raising
`CommandError` (its text, exit 2); `main` also turns the errors every
command can meet (a file that cannot be read, a corrupt recording, a Zenoh
endpoint that does not answer) into one line and exit 2, and, as a last
resort, any other exception, naming its type. ``--debug`` shows the traceback
instead. Exit codes: 0 ok (every property holds), 1 a property is violated
(FAILED), 2 bad input or no answer, 3 inconclusive, 130 interrupted (Ctrl-C), 143
terminated (SIGTERM, handled as Ctrl-C: the same partial summary, `cli.interrupts`).
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
import traceback
from collections.abc import Sequence
from typing import Any

from twinfleet.cli.interrupts import Interrupts
from twinfleet.interfaces.guard import install as refuse_borrowed_ros_names
from twinfleet.robots import EXAMPLES, PICTURES
from twinfleet.runtime.access.errors import CommandError, error_prefix
from twinfleet.runtime.contract.kinds import EXIT_BAD_INPUT, EXIT_INTERRUPTED
from twinfleet.runtime.scenario.examples import add_examples

# the robots' scenarios, by name (``twinfleet check c1a``), and their pictures (`render`)
add_examples(EXAMPLES, PICTURES)

#: The modules whose `register(subparsers)` add the commands, in `--help`'s order, with
#: the commands each adds (tests/checker/test_cli.py holds them to it). A command line
#: that names a command builds the parser of its module only: the others' imports (the
#: live fleet's access and auth, recording, ROS 2, sweeps...) cost `check` a tenth of
#: its start.
COMMAND_MODULES: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("twinfleet.cli.runtime_commands", ("launch", "topic", "service", "node", "param",
                                        "interface", "examples", "record", "play", "bag",
                                        "export", "view", "foxglove")),
    ("twinfleet.cli.render", ("render",)),
    ("twinfleet.checker.commands", ("check", "trace")),
    ("twinfleet.sweep.commands", ("sweep",)),
    ("twinfleet.robots.commands", ("experiment",)),
    ("twinfleet.agreement.commands", ("validate", "replay", "calibrate")),
    ("twinfleet.ros2.commands", ("ros2",)),
)

DESCRIPTION = """\
twinfleet runs a fleet of robot nodes (or any nodes you write in Python) as separate
processes talking over Eclipse Zenoh, with ROS 2-style topics, services, parameters and
tools (node, topic, service, param, interface, bag), and checks the very same node code
exhaustively: the checker explores every interleaving of messages, timers and choices
and proves a property or returns the trace that breaks it.

  twinfleet launch demo               run a scenario live (monitor it from another shell:
  twinfleet node list                 the running fleet is found without --connect)
  twinfleet check c1a                 explore every interleaving
  twinfleet view                      watch it in a browser (`twinfleet foxglove`: in Foxglove)

Every command has --help."""

EPILOG = ("exit codes: 0 ok / every property holds, 1 a property is violated (FAILED), "
          "2 bad input or no answer, 3 inconclusive, 4 a node breaks the node contract, "
          "130 interrupted (Ctrl-C), 143 terminated (SIGTERM); both after a partial summary")


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return f"twinfleet {version('twinfleet')}"
    except PackageNotFoundError:
        return "twinfleet (source checkout, not installed)"


class _VersionAction(argparse.Action):
    """`--version`: the installed version, looked up only when asked (importlib.metadata
    costs every other command ~20 ms of start-up)."""

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                 values: Any, option_string: str | None = None) -> None:
        print(_version())
        parser.exit()


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The full argument parser, or with `command` (one of `COMMAND_MODULES`' names) the
    parser with that command's module's commands only."""
    parser = argparse.ArgumentParser(prog="twinfleet", description=DESCRIPTION, epilog=EPILOG,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action=_VersionAction, nargs=0,
                        help="show the installed version and exit")
    parser.add_argument("--debug", action="store_true",
                        help="show the traceback of an error instead of one line")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for module, names in COMMAND_MODULES:
        if command is None or command in names:
            importlib.import_module(module).register(sub)
    return parser


def named_command(argv: Sequence[str]) -> str | None:
    """The command a command line names, if it names one before anything but --debug
    (then only its module's parser is needed); None for anything else (`--help`, no
    command, an unknown one: the full parser answers those)."""
    words = [w for w in argv if w != "--debug"]
    if words and any(words[0] in names for _, names in COMMAND_MODULES):
        return words[0]
    return None


def main(argv: Sequence[str] | None = None) -> int:
    """Console script `twinfleet`: run the command; every error is one line (module docstring)."""
    args = _parse(build_parser(named_command(sys.argv[1:] if argv is None else argv)), argv)
    with Interrupts() as interrupts:  # SIGTERM stops a command as Ctrl-C does, exit 143
        return interrupts.exit_code(_run(args))


# The positional words that take ``NAME:=VALUE`` overrides, by the commands that have them.
_OVERRIDE_WORDS = ("overrides", "fixed", "scenarios")


def _parse(parser: argparse.ArgumentParser, argv: Sequence[str] | None) -> argparse.Namespace:
    """Parse the command line; ``NAME:=VALUE`` overrides may also come after options
    (`check c1a --quiet r1.speed:=0.4`), where argparse would stop taking positional words:
    they join the command's overrides, in order, so no placement drops or refuses one."""
    args, extra = parser.parse_known_args(argv)
    words = [w for w in extra if ":=" in w and not w.startswith("-")]
    target = next((name for name in _OVERRIDE_WORDS if isinstance(getattr(args, name, None),
                                                                  list)), None)
    if extra != words or (words and target is None):
        return parser.parse_args(argv)  # argparse's own error for what is left
    if words:
        setattr(args, str(target), [*getattr(args, str(target)), *words])
    return args


def _run(args: argparse.Namespace) -> int:
    try:
        refuse_borrowed_ros_names()  # before any node module registers its message types
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        return EXIT_INTERRUPTED
    except BrokenPipeError:  # `twinfleet ... | head`: the reader has what it wanted
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second error at exit
        return 0
    except Exception as exc:  # the last resort: one line, unless --debug
        if args.debug:
            traceback.print_exc()
        print(f"{error_prefix(args)} {error_line(exc)}", file=sys.stderr, flush=True)
        return exc.code if isinstance(exc, CommandError) else EXIT_BAD_INPUT


def error_line(exc: BaseException) -> str:
    """One line for an error that reached `main`, naming what and where."""
    from twinfleet.runtime.access.connection import zenoh_error_text

    if isinstance(exc, CommandError):
        return str(exc)
    if isinstance(exc, OSError) and exc.filename is not None:
        return f"{exc.filename}: {exc.strerror or exc}"
    kind = type(exc)
    if kind.__module__.startswith("zenoh"):
        return f"Zenoh: {zenoh_error_text(exc)}"
    if kind.__module__.startswith("mcap"):
        return f"not a readable MCAP recording: {' '.join(str(exc).split())}"
    text = " ".join(str(exc).split()) or "no details"
    return f"unexpected {kind.__name__}: {text} (run with --debug for the traceback)"


if __name__ == "__main__":
    sys.exit(main())
