"""Whether a simulation has settled: no node state can change any more, whatever the timing.

A simulation (`checker.simulate`) keeps handler runs that made no `ctx.choose`
(`Runner.run_kept`). From a world, follow every event the pending ones can lead to:
each, run on its node's state, must have a kept run that did not read the clock,
left the state unchanged, called no service (a call may time out instead) and did
not `ctx.fail`; the events it sends are followed in turn. If all do, and some timer
among them re-arms itself (so something stays pending for ever and the run reaches
its horizon), then every later handler run is one of these: no node state changes
again and no handler fails, so no property that reads only node states can change.
Due times do not enter: a kept run that did not read the clock has the same outcome
at any time.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, NamedTuple

from twinfleet.checker.runner import Runner
from twinfleet.checker.world import Event
from twinfleet.runtime.contract.context import After, Call, Defer, Fail, Publish, Reply
from twinfleet.runtime.contract.kinds import EventKind


class _Pending(NamedTuple):
    """An event's identity apart from its time: what `settled` follows."""

    target: int
    kind: EventKind
    method: str
    sender: int
    reply_to: str
    key: bytes


def settled(runner: Runner, states: tuple[bytes, ...], pending: Sequence[Event]) -> bool:
    """Whether the world of node `states` and `pending` events has settled (module
    docstring); False: not known to be (a run not kept, a state changed, a call, a
    `ctx.fail`, a late event, no timer that keeps the fleet going)."""
    if any(ev.sk[3] for ev in pending):  # a deadline miss is a failure to come
        return False
    todo = [_Pending(ev.target, ev.kind, ev.method, ev.sender, ev.reply_to, ev.key)
            for ev in pending]
    seen: set[_Pending] = set()
    looping = False
    while todo:
        item = todo.pop()
        if item in seen:
            continue
        seen.add(item)
        data = states[item.target]
        kept = runner.kept(data, item.key)
        if kept is None or (kept[0] is not data and kept[0] != data):
            return False
        follows = _following(runner, item, kept[1], kept[2])
        if follows is None:
            return False
        looping = looping or item.kind is EventKind.PERIODIC or item in follows
        todo += follows
    return looping


def _following(runner: Runner, item: _Pending, effects: Sequence[Any], reply: Any
               ) -> list[_Pending] | None:
    """The events a kept run of `item` sends, as `settled` follows them (None: it fails,
    or it calls a service, whose outcome is more than the kept run's, or defers or sends a
    reply, which `settled` does not follow)."""
    i, out = item.target, []
    subscribers = runner.topology.subscribers
    for eff in effects:
        match eff:
            case Publish(topic=topic, msg=msg):
                out += [_Pending(j, EventKind.DELIVERY, method, i, "",
                                 runner.key_of(EventKind.DELIVERY, j, method, i, "", (msg,)))
                        for j, method, _ in subscribers.get(topic, ())]
            case Call() | Fail() | Defer() | Reply():
                return None
            case After(handler=method, args=args):
                out.append(_Pending(i, EventKind.TIMER, method, i, "",
                                    runner.key_of(EventKind.TIMER, i, method, i, "", args)))
    if item.kind is EventKind.REQUEST:
        out.append(_Pending(item.sender, EventKind.REPLY, item.reply_to, i, "",
                            runner.key_of(EventKind.REPLY, item.sender, item.reply_to, i, "",
                                          (reply,))))
    return out
