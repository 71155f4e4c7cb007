"""Viewers: the web viewer and the Foxglove bridge, and what they draw.
"""

__all__ = [
    "foxglove_bridge",
    "scene_finder",
    "viewer",
    "viewstate",
]
