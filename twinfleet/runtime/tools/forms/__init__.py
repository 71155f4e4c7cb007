"""The fleet's data in the forms viewers read: JSON values and schemas, and Foxglove's
well-known messages. Below both the recordings (the export) and the viewers (the web
viewer, the Foxglove bridge), which share them through here.
"""

__all__ = [
    "foxglove_scene",
    "json_form",
]
