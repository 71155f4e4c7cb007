"""The pure rules under the live checks (runtime.core.guard, runtime.access.fleetauth), without a fleet."""

from __future__ import annotations

import math

import pytest

from tests.integration.reliability_nodes import Tick
from twinfleet.nodes.msgs import ObstacleScan, PathRequest, RobotPose
from twinfleet.runtime.access.fleetauth import FleetCredentials, listen_problem, loopback_only
from twinfleet.runtime.contract.dispatch import declared_message_type
from twinfleet.runtime.core.guard import (
    DEFAULT_LIMIT,
    WINDOW,
    Admission,
    Rejected,
    ReplayWindow,
    Role,
    Stamp,
    authentic,
    check_message,
    opened,
    payload_limit,
    sign,
    signer,
)
from twinfleet.runtime.core.statistics import Rejection


def test_a_tag_binds_key_expression_and_payload() -> None:
    key, other = b"k" * 32, b"o" * 32
    tag = sign(key, "twinfleet/f/poses", b"abc")
    assert authentic(key, "twinfleet/f/poses", b"abc", tag)
    assert authentic(key, "twinfleet/f/poses", b"abc", signer(key, "twinfleet/f/poses")(b"abc"))
    assert not authentic(other, "twinfleet/f/poses", b"abc", tag)
    assert not authentic(key, "twinfleet/f/collisions", b"abc", tag)  # replayed elsewhere
    assert not authentic(key, "twinfleet/f/poses", b"abd", tag)
    assert not authentic(key, "twinfleet/f/poses", b"abc", None)
    assert signer(None, "x")(b"abc") is None


def test_a_stamp_numbers_a_senders_samples_and_cannot_be_altered() -> None:
    key, where = b"k" * 32, "twinfleet/f/poses"
    attach = signer(key, where)
    first, second = attach(b"a"), attach(b"a")
    one, two = opened(key, where, b"a", first), opened(key, where, b"a", second)
    assert one is not None and two is not None
    assert (one.role, one.sender, one.sequence) == (Role.MEMBER, two.sender, 0) and two.sequence == 1
    assert opened(key, where, b"a", signer(key, where)(b"a")).sender != one.sender  # per sender
    renumbered = first[:-1] + bytes([first[-1] + 5])  # a replay given a fresh number
    assert opened(key, where, b"a", renumbered) is None
    recorded = opened(key, where, b"a", signer(key, where, Role.RECORDED)(b"a"))
    assert recorded is not None and recorded.role is Role.RECORDED
    as_member = signer(key, where, Role.RECORDED)(b"a")
    assert opened(key, where, b"a", as_member[:16] + bytes([0]) + as_member[17:]) is None


def test_the_replay_window_lets_each_number_through_once() -> None:
    window, where = ReplayWindow(), "twinfleet/f/poses"
    stamp = lambda n, sender=7: Stamp(Role.MEMBER, sender, n)  # noqa: E731
    assert window.fresh(where, stamp(10))
    assert not window.fresh(where, stamp(10))  # the same sample again
    assert window.fresh(where, stamp(8)) and not window.fresh(where, stamp(8))  # late, once
    assert window.fresh(where, stamp(10, sender=8))  # another sender
    assert window.fresh("twinfleet/f/other", stamp(10))  # another key expression
    assert window.fresh(where, stamp(10 + WINDOW))
    assert not window.fresh(where, stamp(9))  # now older than the window: refused
    assert window.fresh(where, stamp(11))  # inside the window, never seen
    assert not window.fresh(where, stamp(11))


@pytest.mark.parametrize("cell", [(math.nan, 1), (1, math.inf), ("a", "b"), (1, 2, 3), (True, 4),
                                  (1.5, 2)])
def test_a_cell_that_is_not_two_integers_is_invalid(cell) -> None:
    with pytest.raises(Rejected) as info:
        check_message(RobotPose("r1", cell, 0, 1))
    assert info.value.reason is Rejection.INVALID and "RobotPose.cell" in str(info.value)


def test_valid_messages_pass_and_nested_tuples_are_checked() -> None:
    check_message(RobotPose("r1", (3, 4), 0, 1))
    check_message(ObstacleScan("r1", ((1, 2), (3, 4))))
    check_message(PathRequest("r1", (1, 2), (3, 4), final=False))
    with pytest.raises(Rejected):
        check_message(ObstacleScan("r1", ((1, 2), (3, "x"))))
    with pytest.raises(Rejected):
        check_message(PathRequest("r1", (1, 2), (3, 4), final="yes"))


def test_the_handler_annotation_names_the_only_type_it_takes() -> None:
    from twinfleet.nodes.robot import Robot

    assert declared_message_type(Robot, "on_scan") is ObstacleScan
    admit = Admission(ObstacleScan)
    with pytest.raises(Rejected) as info:
        admit(RobotPose("r1", (1, 2), 0, 0))
    assert info.value.reason is Rejection.WRONG_TYPE
    admit(ObstacleScan("r1", ()))
    Admission(None)(Tick("s", 1))  # no annotation: any registered type


def test_the_payload_limit_is_sized_to_the_map() -> None:
    assert payload_limit(50, 50) == DEFAULT_LIMIT
    assert payload_limit(1000, 1000) == 2 * 1000 * 1000 + 4096
    assert payload_limit(1000, 1000, configured=5000) == 5000


def test_listen_needs_loopback_tls_or_an_explicit_insecure_flag() -> None:
    assert loopback_only("tcp/127.0.0.1:7447") and loopback_only("tcp/[::1]:7447")
    assert not loopback_only("tcp/0.0.0.0:7447") and not loopback_only("tcp/10.0.0.2:7447")
    assert listen_problem("tcp/127.0.0.1:7447", insecure=False) is None
    assert listen_problem("tls/10.0.0.2:7447", insecure=False) is None
    assert listen_problem("tcp/10.0.0.2:7447", insecure=True) is None
    why = listen_problem("tcp/0.0.0.0:7447", insecure=False)
    assert why and "--insecure-listen" in why and "clear text" in why


def test_each_launch_draws_fresh_secrets() -> None:
    a, b = FleetCredentials.fresh(), FleetCredentials.fresh()
    assert a.key != b.key and a.node.password != b.node.password
    assert a.monitor.user == "monitor" and a.monitor.password != a.node.password
    env = a.node_env()
    assert bytes.fromhex(env["TWINFLEET_FLEET_KEY"]) == a.key
