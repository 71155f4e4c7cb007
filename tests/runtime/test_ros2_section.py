"""The scenario's `ros2:` section: defaults, the inbound routes as pairs, one-line errors."""

from __future__ import annotations

import pytest

from twinfleet.runtime.scenario.config import DEFAULT_ROS2_ROUTER, Ros2Config
from twinfleet.runtime.scenario.files import copy_example
from twinfleet.runtime.scenario.spec import ScenarioError, load_scenario


def _with(tmp_path, section: str):
    path = copy_example("headon", tmp_path)[0][0]
    path.write_text(path.read_text() + section)
    return load_scenario(path)


def test_no_section_no_bridge_and_an_empty_one_takes_the_defaults(tmp_path):
    assert load_scenario("headon").ros2 is None
    assert _with(tmp_path, "ros2: {}\n").ros2 == Ros2Config()
    assert Ros2Config().router == DEFAULT_ROS2_ROUTER == "tcp/127.0.0.1:7447"


def test_inbound_routes_read_as_pairs(tmp_path):
    cfg = _with(tmp_path, "ros2: {domain: 7, router: tcp/127.0.0.1:17447, "
                          "inbound: {/goal_pose: /r1/goal}, mapping: 'm:M'}\n").ros2
    assert cfg == Ros2Config(7, "tcp/127.0.0.1:17447", (("/goal_pose", "/r1/goal"),), "m:M")


@pytest.mark.parametrize(("section", "said"), [
    ("ros2: {domain: 300}\n", "ros2.domain: expected a ROS domain id 0..232"),
    ("ros2: {router: nowhere}\n", "ros2.router: expected a Zenoh endpoint"),
    ("ros2: {inbound: {goal_pose: /r1/goal}}\n", "ros2.inbound: expected a mapping"),
    ("ros2: {mapping: nocolon}\n", "ros2.mapping: expected 'module:Mapping'"),
    ("ros2: {domian: 1}\n", "ros2.domian: unknown key"),
])
def test_a_bad_section_is_one_line_naming_the_setting(tmp_path, section, said):
    with pytest.raises(ScenarioError, match=said.replace("(", r"\(")):
        _with(tmp_path, section)
