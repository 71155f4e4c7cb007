"""`launch --listen HOST:0` (tcp/ and tls/) takes a free port of that host and tells the nodes
and the registry the real one: the run passes, and the launcher names the port it took."""

from __future__ import annotations

import re

import pytest

from tests.adversarial.fleets import expect, run_launch, write_scenario

pytestmark = [pytest.mark.slow, pytest.mark.timeout(60)]


@pytest.mark.parametrize("scheme", ["tcp", "tls"])
def test_port_zero_is_a_free_port_the_nodes_are_told(tmp_path, scheme):
    path = write_scenario(tmp_path, f"zero_{scheme}", [{"name": "counter", "class": "Counter"}],
                          [{"name": "counts", "kind": "eventually", "expr": "counter.count >= 2"}])
    out = expect(run_launch(path, "--listen", f"{scheme}/127.0.0.1:0", "--timeout", "1.5"), 0,
                 "result: PASSED")
    port = re.search(rf"fleet 'zero_{scheme}' on {scheme}/127\.0\.0\.1:(\d+) ", out)
    assert port and int(port.group(1)) > 0, out
    assert "Traceback" not in out, out
