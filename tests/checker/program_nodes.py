"""A node that runs a small program from its parameters: random node systems without classes.

`ProgramNode` declares a fixed set of entry points (start, three namespaced
topics and one shared topic with different priorities, a service, two timer
handlers, a reply handler) and runs, for each, the list of actions its
`program` parameter gives for it. A generated system is then just a
scenario mapping: the same two classes (`PeriodicProgramNode` adds an
`@every` timer) with different parameters, so it can be written as YAML,
printed by hypothesis when it shrinks a failure, and checked or run live like
any other scenario. `tests/checker/program_systems.py` draws such systems.

A program is a JSON object (a string parameter: one YAML scalar, quick to
load) from handler name (`HANDLERS`) to a list of actions; every action is a
JSON list:

    ["pub", topic]              publish Token(ttl - 1, regs[0]) on topic (if ttl > 0)
    ["echo", topic]             publish Token(ttl, regs[0]): the ttl is NOT spent, so two
                                echoing handlers make a zero-time cycle (Rule 1 never lets
                                time pass), what a reduction's cycle proviso must handle
    ["after", delay_ms, slot]   ctx.after(delay_ms, t<slot>, ttl - 1)     (if ttl > 0)
    ["call", service, timeout]  ctx.call(service, Token(ttl - 1, regs[0]), on_reply)
                                with timeout_ms=timeout                   (if ttl > 0)
    ["add", reg, k]             regs[reg] = (regs[reg] + k) % MOD
    ["max", reg, k]             regs[reg] = max(regs[reg], k): never lowers a register
    ["take", reg]               regs[reg] = (value of the handled input) % MOD
    ["if", reg, v, then, else]  run `then` if regs[reg] == v, else `else` (action lists)
    ["choose", [a, b, ...]]     run one of the action lists, picked by ctx.choose
    ["fail", reg, v]            ctx.fail(...) if regs[reg] == v

`ttl` is what bounds every system but echoes: the start handler and the periodic tick
run with `params.ttl`, every other handler with the ttl its input carries,
and nothing is sent on with ttl 0, so every chain of events ends and node
states (two registers mod `MOD`) are finite. A service replies
Token(ttl - 1, regs[0]); a `CallError` (no server, or a lost request timing
out) reaches `on_reply` as ttl 0 and value MOD - 1.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from twinfleet import (
    CallError,
    Context,
    Node,
    QoS,
    Reliability,
    every,
    handler,
    message,
    on_start,
    service,
    subscribe,
)

MOD = 3  # register values are 0..MOD-1
REGISTERS = 2

#: Handler name -> priority of that entry point (lower runs first among simultaneous events).
PRIORITIES: Mapping[str, int] = {"start": 0, "in0": 0, "in1": 1, "in2": 3, "bus": 2, "svc": 1,
                                 "t0": 0, "t1": 2, "reply": 1, "tick": 0}
HANDLERS = tuple(PRIORITIES)
INPUT_TOPICS = ("in0", "in1", "in2")  # relative: /<node>/in0 ...
BUS = "/bus"  # every program node subscribes
SERVICE = "svc"  # relative: /<node>/svc
TIMER_SLOTS = 2  # t0, t1


@message("twinfleet_program/Token")
class Token:
    """What program nodes send: a time-to-live and a register value."""

    ttl: int = 0
    value: int = 0


class ProgramError(ValueError):
    """A program parameter that does not follow the action grammar."""


@dataclass(frozen=True)
class ProgramParams:
    """Parameters of a program node."""

    program: str = "{}"  # JSON: handler name -> action list (see the module docstring)
    ttl: int = 2
    period_ms: int = 20  # PeriodicProgramNode only


@dataclass
class ProgramState:
    """The registers; everything a program can change."""

    regs: tuple[int, ...] = (0,) * REGISTERS


def _check_actions(actions: Any, where: str) -> None:
    if not isinstance(actions, Sequence) or isinstance(actions, str):
        raise ProgramError(f"{where}: expected a list of actions, got {actions!r}")
    for i, act in enumerate(actions):
        _check_action(act, f"{where}[{i}]")


def _check_action(act: Any, where: str) -> None:
    if not isinstance(act, Sequence) or isinstance(act, str) or not act:
        raise ProgramError(f"{where}: expected an action list such as ['add', 0, 1], got {act!r}")
    op, args = act[0], list(act[1:])
    shapes = {"pub": (str,), "echo": (str,), "after": (int, int), "call": (str, int), "add": (int, int),
              "max": (int, int), "take": (int,), "fail": (int, int)}
    if op in shapes:
        if len(args) != len(shapes[op]) or not all(isinstance(a, t) for a, t in
                                                   zip(args, shapes[op], strict=True)):
            raise ProgramError(f"{where}: {op} takes {[t.__name__ for t in shapes[op]]}, "
                               f"got {args!r}")
        if op in ("add", "max", "take", "fail") and not 0 <= args[0] < REGISTERS:
            raise ProgramError(f"{where}: register {args[0]} out of range")
        if op == "after" and not (args[0] >= 0 and 0 <= args[1] < TIMER_SLOTS):
            raise ProgramError(f"{where}: after needs delay >= 0 and slot < {TIMER_SLOTS}")
    elif op == "if":
        if len(args) != 4 or not 0 <= args[0] < REGISTERS:
            raise ProgramError(f"{where}: if takes reg, value, then-actions, else-actions")
        _check_actions(args[2], f"{where}.then")
        _check_actions(args[3], f"{where}.else")
    elif op == "choose":
        if len(args) != 1 or not args[0]:
            raise ProgramError(f"{where}: choose takes one non-empty list of action lists")
        for k, branch in enumerate(args[0]):
            _check_actions(branch, f"{where}.branch{k}")
    else:
        raise ProgramError(f"{where}: unknown action {op!r}")


class ProgramNode(Node):
    """Runs, for each entry point, the actions `params.program` lists for it."""

    Params = ProgramParams

    def configure(self) -> None:
        try:
            program = json.loads(self.params.program)
        except json.JSONDecodeError as exc:
            raise ProgramError(f"{self.name}: program is not JSON: {exc}") from None
        if not isinstance(program, Mapping):
            raise ProgramError(f"{self.name}: program must map handler names to action lists")
        for name, actions in program.items():
            if name not in HANDLERS:
                raise ProgramError(f"{self.name}: unknown handler {name!r}; "
                                   f"expected one of {', '.join(HANDLERS)}")
            _check_actions(actions, f"{self.name}.{name}")
        self.program = {name: program.get(name, ()) for name in HANDLERS}

    def initial_state(self) -> ProgramState:
        return ProgramState()

    # -- the interpreter --------------------------------------------------------

    def _run(self, ctx: Context, name: str, ttl: int, value: int) -> None:
        self._actions(ctx, self.program[name], ttl, value)

    def _actions(self, ctx: Context, actions: Sequence[Any], ttl: int, value: int) -> None:
        for act in actions:
            self._action(ctx, act, ttl, value)

    def _action(self, ctx: Context, act: Sequence[Any], ttl: int, value: int) -> None:
        op = act[0]
        regs = list(self.state.regs)
        if op == "pub" and ttl > 0:
            ctx.publish(act[1], Token(ttl - 1, regs[0]))
        elif op == "echo" and ttl > 0:
            ctx.publish(act[1], Token(ttl, regs[0]))
        elif op == "after" and ttl > 0:
            ctx.after(act[1], self.t1 if act[2] else self.t0, ttl - 1)
        elif op == "call" and ttl > 0:
            ctx.call(act[1], Token(ttl - 1, regs[0]), self.on_reply, timeout_ms=act[2])
        elif op == "add":
            regs[act[1]] = (regs[act[1]] + act[2]) % MOD
        elif op == "max":
            regs[act[1]] = max(regs[act[1]], act[2] % MOD)
        elif op == "take":
            regs[act[1]] = value % MOD
        elif op == "fail" and regs[act[1]] == act[2]:
            ctx.fail(f"register {act[1]} is {act[2]}")
        elif op == "if":
            self._actions(ctx, act[3] if regs[act[1]] == act[2] else act[4], ttl, value)
            return
        elif op == "choose":
            self._actions(ctx, ctx.choose(act[1]), ttl, value)
            return
        self.state.regs = tuple(regs)

    # -- entry points -------------------------------------------------------------

    @on_start
    def start(self, ctx: Context) -> None:
        self._run(ctx, "start", self.params.ttl, 0)

    @subscribe("in0", priority=PRIORITIES["in0"])
    def on_in0(self, ctx: Context, msg: Token) -> None:
        self._run(ctx, "in0", msg.ttl, msg.value)

    @subscribe("in1", priority=PRIORITIES["in1"])
    def on_in1(self, ctx: Context, msg: Token) -> None:
        self._run(ctx, "in1", msg.ttl, msg.value)

    @subscribe("in2", priority=PRIORITIES["in2"])
    def on_in2(self, ctx: Context, msg: Token) -> None:
        self._run(ctx, "in2", msg.ttl, msg.value)

    @subscribe(BUS, priority=PRIORITIES["bus"])
    def on_bus(self, ctx: Context, msg: Token) -> None:
        self._run(ctx, "bus", msg.ttl, msg.value)

    @service(SERVICE, priority=PRIORITIES["svc"])
    def serve(self, ctx: Context, req: Token) -> Token:
        self._run(ctx, "svc", req.ttl, req.value)
        return Token(max(req.ttl - 1, 0), self.state.regs[0])

    @handler(priority=PRIORITIES["t0"])
    def t0(self, ctx: Context, ttl: int) -> None:
        self._run(ctx, "t0", ttl, 0)

    @handler(priority=PRIORITIES["t1"])
    def t1(self, ctx: Context, ttl: int) -> None:
        self._run(ctx, "t1", ttl, 0)

    @handler(priority=PRIORITIES["reply"])
    def on_reply(self, ctx: Context, reply: Token | CallError) -> None:
        if isinstance(reply, CallError):
            self._run(ctx, "reply", 0, MOD - 1)
        else:
            self._run(ctx, "reply", reply.ttl, reply.value)


class ShallowProgramNode(ProgramNode):
    """A program node whose QoS can lose messages (Rule 6): its `/bus` subscription keeps
    one waiting message (KEEP_LAST depth 1) and its `in2` one is BEST_EFFORT."""

    @subscribe(BUS, priority=PRIORITIES["bus"], qos=QoS(depth=1))
    def on_bus(self, ctx: Context, msg: Token) -> None:
        self._run(ctx, "bus", msg.ttl, msg.value)

    @subscribe("in2", priority=PRIORITIES["in2"], qos=QoS(Reliability.BEST_EFFORT, depth=2))
    def on_in2(self, ctx: Context, msg: Token) -> None:
        self._run(ctx, "in2", msg.ttl, msg.value)


class PeriodicProgramNode(ProgramNode):
    """A program node whose `tick` actions also run every `params.period_ms` ms."""

    @every("period_ms", priority=PRIORITIES["tick"])
    def tick(self, ctx: Context) -> None:
        self._run(ctx, "tick", self.params.ttl, 0)


class CommutingProgramNode(ProgramNode):
    """A program node whose `/bus` handler is declared `commutes=True` (the generator gives
    it programs whose pairs of messages commute wherever they do at all: adds, sends)."""

    @subscribe(BUS, priority=PRIORITIES["bus"], commutes=True)
    def on_bus(self, ctx: Context, msg: Token) -> None:
        self._run(ctx, "bus", msg.ttl, msg.value)
