"""Nodes that break the node contract the way users' first nodes do (tests/checker/
test_contract_breaches.py): each class is one mistake, and the checker must name it.

This module imports `random`, `time`, `datetime`, `uuid` and `os` on purpose; the
load-time lint (runtime.scenario.lint) warns about it, which the tests check too.
"""

from __future__ import annotations

import datetime
import os
import random
import time
import uuid
from dataclasses import dataclass
from random import random as bound_random
from typing import Any

import numpy as np

from twinfleet import Context, Node, String, handler, on_start, service, subscribe

COUNTER = [0]  # a module-level counter: state outside self.state


@dataclass
class Box:
    """A state with one field of any type."""

    value: Any = 0


class _Base(Node):
    def initial_state(self) -> Box:
        return Box()


class RandomInStart(_Base):
    """random.random() in @on_start (the issue's first mistake)."""

    @on_start
    def begin(self, ctx: Context) -> None:
        self.state.value = int(random.random() * 1000)
        ctx.publish("/hello", String("hi"))


class Hello(_Base):
    """Listens on /hello (so RandomInStart's topic is heard)."""

    @subscribe("/hello")
    def on_hello(self, ctx: Context, msg: String) -> None:
        self.state.value += 1


class GlobalCounter(_Base):
    """Counts ticks in a module-level list."""

    @on_start
    def begin(self, ctx: Context) -> None:
        ctx.after(10, self.tick)

    @handler
    def tick(self, ctx: Context) -> None:
        COUNTER[0] += 1
        self.state.value = COUNTER[0] % 3
        if self.state.value:
            ctx.after(10, self.tick)


class ClassCounter(_Base):
    """Counts in a class attribute."""

    seen = 0

    @on_start
    def begin(self, ctx: Context) -> None:
        ctx.after(10, self.tick)

    @handler
    def tick(self, ctx: Context) -> None:
        ClassCounter.seen += 1
        self.state.value = ClassCounter.seen


class HiddenTally(_Base):
    """One handler bumps a class-level tally, another reads it: re-running either alone
    changes nothing, yet the tally is state."""

    tally = 0

    @on_start
    def begin(self, ctx: Context) -> None:
        ctx.after(10, self.bump)

    @handler
    def bump(self, ctx: Context) -> None:
        HiddenTally.tally += 1
        ctx.after(10, self.read)

    @handler
    def read(self, ctx: Context) -> None:
        self.state.value = HiddenTally.tally > 1


class WallClock(_Base):
    """Stores time.time() in its state."""

    @on_start
    def begin(self, ctx: Context) -> None:
        ctx.after(100, self.stamp)

    @handler
    def stamp(self, ctx: Context) -> None:
        self.state.value = time.time()


class BoundRandom(_Base):
    """Uses `from random import random`, bound before the checker's probe."""

    @on_start
    def begin(self, ctx: Context) -> None:
        ctx.after(5, self.roll)

    @handler
    def roll(self, ctx: Context) -> None:
        self.state.value = bound_random()


class DateNow(_Base):
    """Stores datetime.now() as text."""

    @on_start
    def begin(self, ctx: Context) -> None:
        self.state.value = datetime.datetime.now().isoformat()


class Sleeper(_Base):
    """Blocks in a handler."""

    @on_start
    def begin(self, ctx: Context) -> None:
        time.sleep(0.001)


class UuidServer(_Base):
    """A service that answers with a fresh uuid4."""

    @service("/ident")
    def ident(self, ctx: Context, req: String) -> String:
        return String(str(uuid.uuid4()))


class UuidCaller(_Base):
    """Calls /ident once."""

    @on_start
    def begin(self, ctx: Context) -> None:
        ctx.call("/ident", String("who"), self.on_ident)

    @handler
    def on_ident(self, ctx: Context, reply: Any) -> None:
        self.state.value = 1


class Urandom(_Base):
    """Draws bytes from os.urandom."""

    @on_start
    def begin(self, ctx: Context) -> None:
        self.state.value = os.urandom(4)


class NumpyRandom(_Base):
    """Draws from numpy's global generator."""

    @on_start
    def begin(self, ctx: Context) -> None:
        self.state.value = float(np.random.random())


class LambdaTimer(_Base):
    """Passes a lambda to ctx.after."""

    @on_start
    def begin(self, ctx: Context) -> None:
        ctx.after(10, lambda c: None)


@dataclass(frozen=True)
class Dock:
    """A dataclass meant as a message, never registered with @message."""

    slot: int


class UnregisteredMessage(_Base):
    """Publishes a dataclass that is not a registered message."""

    tool_topics = ("/dock",)

    @on_start
    def begin(self, ctx: Context) -> None:
        ctx.publish("/dock", Dock(1))


class UnhashableArgs(_Base):
    """Passes a list as a timer argument."""

    @on_start
    def begin(self, ctx: Context) -> None:
        ctx.after(10, self.later, [1, 2])

    @handler
    def later(self, ctx: Context, items: Any) -> None:
        self.state.value = len(items)


class ObjectInState(_Base):
    """Keeps an arbitrary object in its state."""

    @on_start
    def begin(self, ctx: Context) -> None:
        self.state.value = object()


class FunctionInState(_Base):
    """Keeps a callback in its state."""

    @subscribe("/hello")
    def on_hello(self, ctx: Context, msg: String) -> None:
        self.state.value = print


class AttributeCounter(_Base):
    """Counts in an attribute of self other than state."""

    def configure(self) -> None:
        self.ticks = 0

    @on_start
    def begin(self, ctx: Context) -> None:
        ctx.after(10, self.tick)

    @handler
    def tick(self, ctx: Context) -> None:
        self.ticks += 1
        self.state.value = self.ticks % 2


class BadInitialState(Node):
    """An initial state that cannot be encoded."""

    def initial_state(self) -> Box:
        return Box(object())

    @on_start
    def begin(self, ctx: Context) -> None:
        self.state.value = 1


class Pinger(_Base):
    """Publishes one /hello at the start (a well-behaved companion)."""

    @on_start
    def begin(self, ctx: Context) -> None:
        ctx.publish("/hello", String("hi"))


TICKS = [0]  # LeakyTicker's module-level counter (tests reset it)


class LeakyTicker(_Base):
    """Ticks three times, counting in a module-level list: a rebuilt path goes elsewhere."""

    @on_start
    def begin(self, ctx: Context) -> None:
        ctx.after(10, self.tick)

    @handler
    def tick(self, ctx: Context) -> None:
        TICKS[0] += 1
        if TICKS[0] < 4:
            ctx.after(10, self.tick)
        self.state.value = TICKS[0]
