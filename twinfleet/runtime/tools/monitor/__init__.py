"""The ROS 2-style monitors: a fleet's graph, the graph and data verbs, typed payloads,
and the tap that hears every topic.
"""

__all__ = [
    "data_verbs",
    "graph",
    "graph_verbs",
    "payload",
    "tap",
]
