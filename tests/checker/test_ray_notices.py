"""Ray's notices stay out of the user's terminal: while a cluster starts or stops, what Ray's
Python side logs and what its C++ core (and the processes it starts) write on file
descriptor 2 go to a log file; the command's own lines before and after still reach stderr."""

from __future__ import annotations

import logging
import os
import sys
import tempfile

from twinfleet.checker.cluster.ray_host import ray_log_path, ray_notices


def test_ray_notices_go_to_the_log_not_to_stderr(tmp_path, monkeypatch, capfd):
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    ray_logger = logging.getLogger("ray")
    loud = logging.StreamHandler(sys.stderr)  # as Ray's own handler on import
    ray_logger.addHandler(loud)
    try:
        print("before", file=sys.stderr, flush=True)
        with ray_notices() as path:
            logging.getLogger("ray._private.auth").warning("Token authentication is enabled")
            os.write(2, b"[C++] core notice\n")
        print("after", file=sys.stderr, flush=True)
        assert ray_logger.handlers[-1] is loud  # put back
    finally:
        ray_logger.removeHandler(loud)
    err = capfd.readouterr().err
    assert err == "before\nafter\n"
    assert path == ray_log_path() and path.parent == tmp_path
    text = path.read_text()
    assert "Token authentication is enabled" in text and "[C++] core notice" in text
