"""`twinfleet view` in headless Debian chromium, live and on a trace.

The viewer starts first and waits for the router; then C1a is launched at time
scale 10 on the same loopback endpoint. The page must draw the 50x50 map and
all five robots (checked on canvas pixels, not only on the page's state), show
every robot moving, a selected robot's scan and the status panel, and end with
every robot arrived. Screenshots go to out/test-artifacts/.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import pytest
from viewer_support import ARTIFACTS, ROOT, api, free_port, get_json, poll, printed_url

pytestmark = [pytest.mark.slow, pytest.mark.timeout(80)]

CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--no-first-run"]
ROBOTS = ["r1", "r2", "r3", "r4", "r5"]
SCENARIO_STARTS = {"r1": (5, 5), "r2": (5, 15), "r3": (5, 25), "r4": (5, 35), "r5": (5, 45)}


@pytest.fixture
def browser_page(tmp_path):
    """A page in a fresh headless chromium profile (Playwright drives Debian's chromium)."""
    if not CHROMIUM.exists():
        pytest.skip("Debian chromium is not installed at /usr/bin/chromium "
                    "(.ci/run installs it: apt-get install -y chromium)")
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        context = pw.chromium.launch_persistent_context(
            str(tmp_path / "chromium-profile"), executable_path=str(CHROMIUM), headless=True,
            args=CHROMIUM_ARGS, viewport={"width": 1320, "height": 800})
        try:
            page = context.new_page()
            page.set_default_timeout(20_000)
            yield page
        finally:
            context.close()


def _start_viewer(cli, *args: str) -> str:
    port = free_port()
    viewer = cli("view", "--port", str(port), *args, log="viewer.log")
    url = printed_url(viewer.log)  # the page opens with the URL the viewer printed (its token)
    poll(lambda: get_json(api(url, "api/info")), 15, "the viewer's HTTP server")
    return url


def _assert_drawn(page, robots: list[str]) -> dict:
    probe = page.evaluate("() => { twinfleetView.draw(); return twinfleetView.probe(); }")
    assert probe["map"] is not None and probe["map"]["pixel"] == probe["map"]["expected"], probe["map"]
    assert sorted(probe["robots"]) == robots
    for name, seen in probe["robots"].items():
        assert seen["pixel"] == seen["expected"], f"{name} not drawn in its colour: {seen}"
    return probe


def test_viewer_shows_the_live_c1a_fleet_moving(cli, browser_page):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    url = _start_viewer(cli, "--connect", endpoint, "--fleet", "c1a")
    page = browser_page
    page.goto(url)
    page.wait_for_function("() => window.twinfleetView && twinfleetView.wsOpen")
    launched = time.monotonic()
    cli("launch", str(ROOT / "twinfleet" / "launch" / "c1a.yaml"), "--time-scale", "10", "--listen", endpoint,
        log="fleet.log")

    page.wait_for_function("() => twinfleetView.mapDrawn && twinfleetView.drawnRobots.length === 5")
    first_frame_s = time.monotonic() - launched
    assert page.get_attribute("#world", "data-map") == "50x50"
    assert page.get_attribute("#world", "data-robots") == "5"
    first = _assert_drawn(page, ROBOTS)
    start_places = {name: seen["place"] for name, seen in first["robots"].items()}
    # A viewer opened before the launch keeps every trail from the robot's start cell on
    # (nothing evicted, and no false restart from the map server's lagging clock on scans);
    # the page holds places in cells: the centre of cell (row, col) is (col + 0.5, row + 0.5)
    trails = page.evaluate("() => Object.fromEntries(Object.entries(twinfleetView.robots).map("
                           "([n, r]) => [n, [r.trail.start, r.trail.items[0]]]))")
    assert trails == {n: [0, [c[1] + 0.5, c[0] + 0.5]] for n, c in SCENARIO_STARTS.items()}
    # Zoom (out, so that the whole map stays on the canvas) and pan: the map and the robots
    # are drawn where the page's transform puts them.
    page.evaluate("() => { twinfleetView.zoomAt([0, 0], 0.8); twinfleetView.pan[0] += 40; "
                  "twinfleetView.draw(); }")
    assert page.evaluate("() => [twinfleetView.zoom, twinfleetView.pan]") == [0.8, [40, 0]]
    _assert_drawn(page, ROBOTS)
    page.click("#zoom-reset")
    assert page.evaluate("() => [twinfleetView.zoom, twinfleetView.pan]") == [1, [0, 0]]

    page.wait_for_function(
        """(start) => Object.entries(start).every(([n, c]) => {
             const p = twinfleetView.positions[n]; return p && (p[0] !== c[0] || p[1] !== c[1]); })""",
        arg=start_places)
    all_moved_s = time.monotonic() - launched
    _assert_drawn(page, ROBOTS)

    page.click("tr.robot[data-robot='r3']")
    page.wait_for_function("() => twinfleetView.selected === 'r3' && twinfleetView.robots.r3.scan.length > 0")
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(ARTIFACTS / "viewer-moving.png"))

    try:
        page.wait_for_function("""() => twinfleetView.ended !== null && Object.values(twinfleetView.robots)
                                  .every(r => r.row && r.row.mode === 'arrived')""", timeout=40_000)
    except Exception:  # say what the page had instead
        seen = page.evaluate("() => [twinfleetView.ended, Object.fromEntries(Object.entries("
                             "twinfleetView.robots).map(([n, r]) => [n, r.row]))]")
        state = get_json(api(url, "api/state")) or {}
        server = {n: r.get("row") for n, r in state.get("robots", {}).items()}
        pytest.fail(f"the page did not show the end with every robot arrived: {seen}; "
                    f"the viewer's state: {state.get('ended')}, {server}")
    page.evaluate("() => twinfleetView.draw()")
    rows = page.eval_on_selector_all(
        "#robots tr", "rows => rows.map(r => Array.from(r.cells).map(c => c.textContent))")
    assert [row[1] for row in rows] == ROBOTS
    assert all(row[2] == "arrived" and row[7] == "yes" for row in rows), rows
    page.screenshot(path=str(ARTIFACTS / "viewer.png"))
    figures = {"first_frame_s_after_launch": round(first_frame_s, 2),
               "all_robots_moved_s_after_launch": round(all_moved_s, 2),
               "page_first_frame_ms": page.evaluate("() => twinfleetView.firstFrameMs"),
               "websocket_messages": page.evaluate("() => twinfleetView.messages")}
    (ARTIFACTS / "viewer-figures.json").write_text(json.dumps(figures, indent=1))
    print("viewer figures:", figures)


def test_viewer_steps_through_a_checker_trace(cli, browser_page, tmp_path):
    from twinfleet.checker.driver import CheckOptions, check

    trace = tmp_path / "headon.trace.json"
    result = check(ROOT / "twinfleet" / "launch" / "headon.yaml", CheckOptions(trace_out=str(trace)))
    assert result.status == "violated"
    steps = len(json.loads(trace.read_text())["steps"])
    url = _start_viewer(cli, "--trace", str(trace))
    page = browser_page
    page.goto(url)
    page.wait_for_function("() => twinfleetView.trace && twinfleetView.mapDrawn")
    assert page.evaluate("() => twinfleetView.step") == steps  # opens on the violation
    assert page.is_visible("#robots-panel") and page.is_visible("#collisions-panel")
    _assert_drawn(page, ["r1", "r2"])
    assert page.evaluate("() => twinfleetView.probe() && document.getElementById('collision-count').textContent") == "1"
    page.click("#first")
    assert page.evaluate("() => twinfleetView.step") == 0
    page.wait_for_function("() => JSON.stringify(twinfleetView.positions) === "
                           "'{\"r1\":[1.5,5.5],\"r2\":[10.5,5.5]}'")  # starts (5, 1), (5, 10)
    for _ in range(steps // 2):
        page.keyboard.press("ArrowRight")
    assert page.evaluate("() => twinfleetView.step") == steps // 2
    assert "step" in page.text_content("#step-label")
    page.click("#last")
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(ARTIFACTS / "viewer-trace.png"))


def test_viewer_lists_and_inspects_the_topics_of_a_non_robot_fleet(cli, browser_page):
    # A fleet that is not the robots: the demo (talker, listener, adder, caller) has no map and
    # no robot; the viewer starts before it, without --connect, and finds it in the registry.
    url = _start_viewer(cli)
    page = browser_page
    page.goto(url)
    page.wait_for_function("() => window.twinfleetView && twinfleetView.wsOpen")
    cli("launch", str(ROOT / "twinfleet" / "launch" / "demo.yaml"), "--timeout", "30", log="fleet.log")
    page.wait_for_selector("tr.topic[data-topic='/chatter']")
    row = page.eval_on_selector("tr.topic[data-topic='/chatter']",
                                "r => Array.from(r.cells).map(c => c.textContent)")
    assert row[:2] == ["/chatter", "std_msgs/String"] and int(row[2]) >= 1
    page.click("tr.topic[data-topic='/chatter']")
    page.wait_for_function("() => document.getElementById('inspector').textContent.includes('hello')")
    inspected = json.loads(page.text_content("#inspector"))
    assert inspected["type"] == "std_msgs/String" and inspected["sender"] == "talker"
    assert inspected["data"]["data"].startswith("hello ")
    assert "/chatter" in page.text_content("#inspector-title")
    page.evaluate("() => twinfleetView.draw()")
    assert page.evaluate("() => twinfleetView.mapDrawn") is False
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(ARTIFACTS / "viewer-demo.png"))


USER_TRACE_SCENARIO = """\
name: mine
nodes:
  - {name: talker, class: "twinfleet.nodes.demo:Talker", params: {period_ms: 100}}
  - {name: listener, class: "twinfleet.nodes.demo:Listener"}
properties:
  - {name: talks_little, kind: invariant, expr: "talker.count < 3"}
"""


def test_viewer_steps_through_a_trace_of_a_users_fleet(cli, browser_page, tmp_path):
    from twinfleet.checker.driver import CheckOptions, check

    scenario = tmp_path / "mine.yaml"
    scenario.write_text(USER_TRACE_SCENARIO)
    trace = tmp_path / "mine.trace.json"
    assert check(scenario, CheckOptions(trace_out=str(trace))).status == "violated"
    steps = len(json.loads(trace.read_text())["steps"])
    url = _start_viewer(cli, "--trace", str(trace))
    page = browser_page
    page.goto(url)
    page.wait_for_function("() => twinfleetView.trace !== null")
    assert page.evaluate("() => twinfleetView.step") == steps
    states = page.text_content("#states")
    assert "talker:" in states and '"count":3' in states.replace(" ", ""), states
    assert "→" in page.text_content("#step-info")  # the violation's message
    assert not page.is_visible("#robots-panel")  # no body drawn: no empty robot table
    assert not page.is_visible("#collisions-panel")
    page.click("#first")
    assert "talker:" in page.text_content("#states") and page.evaluate("() => twinfleetView.step") == 0
    page.keyboard.press("ArrowRight")
    assert "talker" in page.text_content("#step-info") or "listener" in page.text_content("#step-info")
    page.screenshot(path=str(ARTIFACTS / "viewer-user-trace.png"))
