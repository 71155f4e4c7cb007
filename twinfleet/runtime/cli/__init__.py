"""The runtime's commands: launch, the monitors, view, foxglove, record, play, export, bag.

May import anything of twinfleet (commands sit on top).
"""

__all__ = [
    "commands",
    "recording_commands",
    "render",
    "viewer_commands",
]
