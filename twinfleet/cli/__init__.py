"""The `twinfleet` command line: the top floor, assembled from the commands each layer registers.

    twinfleet launch|node|topic|service|param|interface|bag   (twinfleet.cli.runtime_commands)
    twinfleet record|play|export                              (twinfleet.cli.recording_commands)
    twinfleet view|foxglove                                   (twinfleet.cli.viewer_commands)
    twinfleet render                                          (twinfleet.cli.render)
    twinfleet check                                           (twinfleet.checker.commands)
    twinfleet experiment                                      (twinfleet.robots.commands)
    twinfleet replay|validate|calibrate                       (twinfleet.agreement.commands)
    twinfleet ros2 bridge                                     (twinfleet.ros2.commands)
    twinfleet sweep                                           (twinfleet.sweep.commands)

Nothing below imports this package; it may import every layer (tests/test_layering.py).
`main` and `build_parser` live in `twinfleet.cli.main`.
"""

from twinfleet.cli.main import build_parser, error_line, main

__all__ = [
    "build_parser",
    "error_line",
    "main",
    "recording_commands",
    "render",
    "runtime_commands",
    "viewer_commands",
]
