"""The ROS 2 commands: `export --ros2` and `bag info BAG/` (called by the runtime's commands).

Each imports the ROS field's libraries when it runs; without the ``ros2`` extra it
says how to install them (exit 2).
"""

from __future__ import annotations

import argparse
import sys

from twinfleet.runtime.fleet.connection import CommandError

INSTALL_HINT = "the ROS 2 bridge needs its libraries: pip install 'twinfleet[ros2]'"


def _need_libraries() -> None:
    try:
        import rosbags  # noqa: F401
    except ImportError:
        raise CommandError(INSTALL_HINT) from None


def export_rosbag2_command(args: argparse.Namespace) -> int:
    """`twinfleet export FILE --ros2 -o BAG/`."""
    _need_libraries()
    from twinfleet.ros2.mapping import MappingError
    from twinfleet.ros2.rosbag import ExportError, export_rosbag2

    try:
        written = export_rosbag2(args.file, args.output, mapping=args.mapping)
    except (ExportError, MappingError, OSError) as exc:
        raise CommandError(f"export --ros2: {exc}") from None
    topics = ", ".join(f"{t} ({n})" for (t, _), n in sorted(written.counts.items()))
    print(f"wrote {args.output}: rosbag2 (MCAP, CDR), {written.messages} messages on "
          f"{len(written.counts)} topics via {written.mapping}: {topics or 'none'}", flush=True)
    return 0


def rosbag2_info(path: str) -> int:
    """`twinfleet bag info BAG/` for a rosbag2 folder."""
    _need_libraries()
    from twinfleet.ros2.rosbag import is_rosbag2, print_bag_info

    if not is_rosbag2(path):
        raise CommandError(f"{path}: a folder but not a rosbag2 bag (no metadata.yaml)")
    try:
        print_bag_info(path, sys.stdout)
    except Exception as exc:  # rosbags raises its own errors for a damaged bag
        raise CommandError(f"{path}: {type(exc).__name__}: {exc}") from None
    return 0
