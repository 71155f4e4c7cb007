"""What `param get` reads of a running rclpy node: the node's ``@info`` answers with the
parameters in force, so a value `param set` changed is shown, not the launch's."""

from __future__ import annotations

from typing import Any

import msgpack
import pytest

from tests.rclpy.oracle import in_process_env
from twinfleet import testing
from twinfleet.rclpy.param_service import SetParameter, set_parameter
from twinfleet.runtime.host.introspect import serve_info

pytestmark = pytest.mark.timeout(60)

in_process_env()


class _Transport:
    """Keeps what `serve_info` serves, as a Zenoh queryable would."""

    def __init__(self) -> None:
        self.served: dict[str, Any] = {}

    def publisher(self, key: str, qos: Any) -> Any:
        return lambda payload: None

    def serve(self, key: str, respond: Any) -> None:
        self.served[key] = respond


def _info(transport: _Transport) -> dict[str, Any]:
    (respond,) = transport.served.values()
    answers: list[bytes] = []
    respond(b"", lambda payload, _kind: answers.append(payload))
    return msgpack.unpackb(answers[0], raw=False)


def test_info_shows_a_parameter_set_while_running():
    scenario = testing.system({"tuner": "tuning:Tuner"}, [testing.eventually("any", "True")])
    node = scenario.node("tuner").instantiate()
    transport = _Transport()
    serve_info(transport, "tuning", node, "tuning:Tuner")
    assert _info(transport)["params"] == {"gain": 1.0, "mode": "auto"}
    accepted = set_parameter(node.rclpy_node, SetParameter("gain", "3.0"))
    refused = set_parameter(node.rclpy_node, SetParameter("gain", "-1.0"))  # the callback says no
    assert accepted.successful and not refused.successful, (accepted, refused)
    assert _info(transport)["params"] == {"gain": 3.0, "mode": "auto"}
