"""The checker on native nodes whose service replies later (tests/checker/deferred_nodes.py):
a `ctx.reply` from a later handler is the reply event the service's return value would
have been, to the caller its token names; relays that answer the wrong caller are found."""

from __future__ import annotations

from tests.checker.deferred_nodes import Asker, Backend, Relay, SloppyRelay
from twinfleet import Context, Node, ReplyToken, on_start, testing
from twinfleet.runtime.contract.kinds import EventKind


def fleet(relay: type[Node], askers: int, *extra: testing.PropertyConfig,
          **settings: object) -> testing.Scenario:
    nodes: dict[str, type[Node]] = {"backend": Backend, "relay": relay}
    properties = list(extra)
    for k in range(askers):
        nodes[f"a{k}"] = Asker
        properties.append(testing.eventually(f"a{k}_answered", f"a{k}.got == 'a{k}'"))
    return testing.system(nodes, properties, **settings)


def test_a_relay_that_answers_later_holds_with_one_and_two_askers():
    one, two = testing.check(fleet(Relay, 1)), testing.check(fleet(Relay, 2))
    assert one.holds and two.holds, (one.explain(), two.explain())
    assert two.states > one.states


def test_both_orders_of_two_deferred_replies_are_explored():
    for first, second in (("a0", "a1"), ("a1", "a0")):
        before = testing.invariant("order", f"not ({first}.got != '' and {second}.got == '')")
        report = testing.check(fleet(Relay, 2, before))
        assert report.violated and report.property == "order", report.explain()


def test_a_relay_that_answers_the_wrong_caller_is_violated_with_a_trace():
    report = testing.check(fleet(SloppyRelay, 2))
    assert report.violated and report.property in ("a0_answered", "a1_answered"), \
        report.explain()
    assert report.trace is not None
    other = {"a0": "a1", "a1": "a0"}
    wrong = [s for s in report.trace["steps"] if s["kind"] == EventKind.REPLY.value
             and s["node"] in other and f"to='{other[s['node']]}'" in s["args"]]
    assert wrong, report.trace["steps"]  # one caller's answer reached the other as its reply
    assert testing.check(fleet(SloppyRelay, 1)).holds  # one caller: nothing to mix up


class Forger(Node):
    """Replies with a token naming a node that is not in the scenario."""

    @on_start
    def start(self, ctx: Context) -> None:
        from tests.checker.deferred_nodes import Answer, Ask

        ctx.reply(ReplyToken("/relay", "ghost", "done", Ask("ghost")), Answer())


def test_a_reply_to_a_caller_that_does_not_exist_is_a_breach():
    report = testing.check(testing.system({"forger": Forger}))
    assert report.breach and "'ghost', which is no node of the scenario" in report.message, \
        report.explain()


class Outside(Node):
    @on_start
    def start(self, ctx: Context) -> None:
        ctx.defer_reply()


def test_defer_reply_outside_a_service_handler_is_a_breach():
    report = testing.check(testing.system({"n": Outside}))
    assert report.breach and "defer_reply() outside a @service handler" in report.message



def test_the_reduction_keeps_every_verdict_of_deferred_replies():
    """A reply from a handler that is not the request's is a send the reduction must learn
    (an edge from the replying handler to the caller): reduced and full searches agree on
    every verdict, with latency too (replies then overtake each other)."""
    for relay, askers in ((Relay, 2), (Relay, 3), (SloppyRelay, 2)):
        for latency in (None, [0, 2]):
            settings = {"check": {"latency": latency}} if latency else {}
            orders = [testing.invariant("order", f"not ({a}.got != '' and {b}.got == '')")
                      for a, b in (("a0", "a1"), ("a1", "a0"))]
            for system in (fleet(relay, askers, **settings),
                           *(fleet(relay, askers, order, **settings) for order in orders)):
                full = testing.check(system, reduction="none")
                reduced = testing.check(system, reduction="por")
                assert (reduced.verdict, reduced.property) == (full.verdict, full.property), \
                    (reduced.explain(), full.explain())
                assert not reduced.holds or reduced.states <= full.states
