"""The robot and map-server handlers, run through `run_handler` alone: no transport, no checker."""

from __future__ import annotations

from pathlib import Path as FsPath

import pytest

from twinfleet.nodes.map_server import MapServer, MapServerParams
from twinfleet.nodes.msgs import Collision, ObstacleScan, Path, PathRequest, RobotPose
from twinfleet.nodes.robot import Robot, RobotParams
from twinfleet.runtime.contract.context import After, Call, Context, Publish
from twinfleet.runtime.contract.dispatch import run_handler
from twinfleet.runtime.contract.messages import CallError, CallFailure

MAP50 = str(FsPath(__file__).resolve().parents[2] / "twinfleet" / "maps" / "map50.yaml")
ROBOTS = ("r1", "r2", "r3", "r4", "r5")


class CountingChooser:
    """Records how many options each choice point offered; answers `pick`."""

    def __init__(self, pick: int = 0) -> None:
        self.offered: list[int] = []
        self.pick = pick

    def choose(self, n: int) -> int:
        self.offered.append(n)
        return min(self.pick, n - 1)


def robot(profile: str = "rebeca", **kw) -> Robot:
    params = RobotParams(map=MAP50, start=(5, 5), goal=(45, 45), speed=0.5, max_wait_ms=1500,
                         profile=profile, **kw)
    return Robot("r1", params, namespace="/r1")


def run(node, method, *args, now=0, chooser=None, reply=False):
    ctx = Context(node, now) if chooser is None else Context(node, now, chooser)
    out = run_handler(node, method, ctx, args, expects_reply=reply)
    assert out.error is None, out.error
    return out


def of_type(effects, cls):
    return [e for e in effects if isinstance(e, cls)]


def test_robot_start_requests_a_path_to_its_goal():
    r = robot()
    out = run(r, "start")
    (call,) = of_type(out.effects, Call)
    assert call.service == "/generate_path"
    assert call.request == PathRequest("r1", (5, 5), (45, 45), True)
    assert call.reply_to == "on_path"
    assert r.state.targets == ((45, 45),)


def test_new_path_starts_the_motion_loop_at_once():
    r = robot()
    run(r, "start")
    out = run(r, "on_path", Path(((6, 6), (7, 7))))
    assert of_type(out.effects, After) == [After(0, "update_moving_status", (True,))]
    assert r.state.moves == ((6, 6), (7, 7))


def test_first_decision_rotates_from_north_to_north_east_in_126_ms():
    r = robot()
    run(r, "on_path", Path(((6, 6),)))
    out = run(r, "update_moving_status", True)
    (pose,) = [e.msg for e in of_type(out.effects, Publish) if e.topic == "/poses"]
    assert pose == RobotPose("r1", (5, 5), 1, 0, False)
    assert of_type(out.effects, After) == [After(126, "update_moving_status", (True,))]


def test_hop_when_the_way_is_clear_and_wait_when_blocked():
    r = robot()
    run(r, "on_path", Path(((6, 5), (7, 5))))
    r.state.dir = 0
    out = run(r, "update_moving_status", True)
    assert r.state.cell == (6, 5)
    assert of_type(out.effects, After) == [After(511, "update_moving_status", (True,))]
    run(r, "on_scan", ObstacleScan("r1", ((8, 5),)))  # two cells ahead blocks (docs/robots.md §4)
    run(r, "update_moving_status", True)
    assert r.state.cell == (6, 5)
    assert r.state.waiting and r.state.waits == 1


@pytest.mark.parametrize(("profile", "expected"), [("rebeca", [2, 9999, 2]), ("fixed", [0, 0, 0])])
def test_front_obstacle_is_the_models_free_hops_ahead_at_each_scan_and_decision(profile, expected):
    r = robot(profile)
    run(r, "on_path", Path(((6, 5), (7, 5))))
    r.state.dir = 0
    seen = []
    # Three cells ahead: 0.7649999999999999 m / 0.255 m truncates to 2, as in the model.
    run(r, "on_scan", ObstacleScan("r1", ((8, 5),)))
    seen.append(r.state.front_obstacle)
    run(r, "on_scan", ObstacleScan("r1", ((5, 8),)))  # beside the robot, not ahead: 9999
    seen.append(r.state.front_obstacle)
    run(r, "on_scan", ObstacleScan("r1", ((7, 5),)))  # two cells ahead: 0.51 / 0.255 = 2
    r.state.front_obstacle = 0 if profile == "fixed" else -1
    run(r, "update_moving_status", True)  # blocked: recomputed at the decision
    seen.append(r.state.front_obstacle)
    assert seen == expected
    assert r.state.waiting


def test_waiting_robot_backs_off_with_twenty_alternatives_in_the_rebeca_profile():
    r = robot()
    run(r, "start")
    run(r, "on_path", Path(((6, 5), (7, 5))))
    r.state.dir = 0
    run(r, "on_scan", ObstacleScan("r1", ((7, 5),)))
    for _ in range(15):  # max_waiting_rounds = round_m(1500/100) = 16
        run(r, "update_moving_status", True)
    assert r.state.waits == 15 and r.state.failures == 0
    chooser = CountingChooser(pick=0)
    out = run(r, "update_moving_status", True, chooser=chooser)
    assert chooser.offered == [20]
    assert r.state.failures == 1
    (call,) = of_type(out.effects, Call)
    assert call.request.final is False
    assert len(r.state.targets) == 2


def test_failed_plans_leave_the_robot_stuck_after_the_third():
    r = robot()
    run(r, "start")
    chooser = CountingChooser()
    for _ in range(3):
        run(r, "on_path", CallError("/generate_path", CallFailure.TIMEOUT, "timeout"), chooser=chooser)
    assert r.state.failures == 3 and r.state.stuck


def server(profile: str = "rebeca") -> MapServer:
    return MapServer("map_server", MapServerParams(map=MAP50, robots=ROBOTS, profile=profile))


def test_map_server_starts_one_scan_loop_per_robot_and_latches_the_map():
    ms = server()
    out = run(ms, "start")
    assert [e.args for e in of_type(out.effects, After)] == [(r,) for r in ROBOTS]
    (grid,) = [e.msg for e in of_type(out.effects, Publish) if e.topic == "/map"]
    assert (grid.width, grid.height) == (50, 50)
    assert sum(1 for b in grid.data if b == 100) == 213  # the model's < 204 threshold


def test_scan_publishes_on_the_robots_topic_and_rearms():
    ms = server()
    out = run(ms, "scan_robot", "r2")
    (pub,) = of_type(out.effects, Publish)
    assert pub.topic == "/r2/scan" and isinstance(pub.msg, ObstacleScan)
    assert of_type(out.effects, After) == [After(100, "scan_robot", ("r2",))]


def test_initial_plan_of_r1_is_the_golden_path():
    ms = server()
    out = run(ms, "generate_path", PathRequest("r1", (5, 5), (45, 45)), reply=True)
    cells = out.reply.cells
    assert cells[:3] == ((6, 6), (7, 7), (8, 8))
    assert cells[-1] == (45, 45) and len(cells) == 41  # RMC's plan (docs/robots.md §3)


@pytest.mark.parametrize(("profile", "offset"), [("rebeca", (1, 1)), ("fixed", (1, 0))])
def test_map_server_counts_a_collision_and_names_both_robots(profile, offset):
    ms = server(profile)
    run(ms, "on_pose", RobotPose("r1", (20, 30), 0, 2))
    out = run(ms, "on_pose", RobotPose("r2", (20 + offset[0], 30 + offset[1]), 0, 2), now=700)
    collisions = [e.msg for e in of_type(out.effects, Publish) if e.topic == "/collisions"]
    assert collisions == [Collision("r2", "r1", (20 + offset[0], 30 + offset[1]), (20, 30), 700)]
    assert ms.state.collisions == 1


def test_map_server_asks_for_shutdown_once_every_robot_is_done():
    ms = server("fixed")
    topics = []
    for i, name in enumerate(ROBOTS):
        out = run(ms, "on_pose", RobotPose(name, (40, 5 + 8 * i), 0, 0, True))
        topics += [e.topic for e in of_type(out.effects, Publish)]
    assert topics.count("/twinfleet/shutdown") == 1


def test_unsafe_speed_is_refused_unless_allowed():
    with pytest.raises(ValueError, match="Eq. 1"):
        Robot("r5", RobotParams(map=MAP50, start=(5, 45), goal=(45, 5), speed=1.0, scan_rate_ms=140,
                                profile="rebeca"))
    Robot("r5", RobotParams(map=MAP50, start=(5, 45), goal=(45, 5), speed=1.0, scan_rate_ms=140,
                            profile="rebeca", allow_unsafe_speed=True))


@pytest.mark.parametrize("cell", [(60, 5), (-1, 3), (10, 20)])
def test_start_outside_the_map_or_in_an_obstacle_is_refused(cell):
    with pytest.raises(ValueError, match="start"):
        Robot("r1", RobotParams(map=MAP50, start=cell, goal=(45, 45)))


def test_report_counts_hops_waits_and_collisions_from_messages():
    from twinfleet.nodes.msgs import RobotStatus
    from twinfleet.nodes.report import FleetReport

    rep = FleetReport(("r1", "r2"))
    assert "/r2/status" in rep.topics()
    for cell in [(5, 5), (5, 5), (6, 6), (7, 6)]:
        rep.on_message("/poses", RobotPose("r1", cell, 1, 2))
    for t, mode in enumerate(["planning", "moving", "waiting", "waiting", "backing_off", "moving",
                              "arrived"]):
        rep.on_message("/r1/status", RobotStatus("r1", mode, (7, 6), (7, 6), 0, 1, 1000 + 700 * t))
    rec = rep.records["r1"]
    assert (rec.hops, rec.waits, rec.backoffs, rec.arrived, rec.arrival_ms) == (2, 1, 1, True, 4200)
    assert rec.distance_m == pytest.approx(0.255 * (2 ** 0.5 + 1))
    assert not rep.passed()  # r2 never arrived
    rep.on_message("/collisions", Collision("r1", "r2", (7, 6), (7, 7), 5000))
    text = rep.render()
    assert "collisions: 1" in text and "r1 (7, 6) <-> r2 (7, 7)" in text
    assert "result" not in text  # the run's result is the live verdict's (runtime.fleet.live_verdict)


@pytest.mark.parametrize(("profile", "hops"), [("fixed", False), ("rebeca", True)])
def test_robot_in_the_neighbouring_diagonal_lane_blocks_only_in_the_fixed_profile(profile, hops):
    r = robot(profile)
    run(r, "on_path", Path(((43, 43),)))
    r.state.cell, r.state.dir = (42, 42), 1
    # Another robot two rows down: 0.36 m ahead and 0.36 m aside of a NE hop.
    run(r, "on_scan", ObstacleScan("r1", ((44, 42),)))
    run(r, "update_moving_status", True)
    assert (r.state.cell == (43, 43)) is hops
