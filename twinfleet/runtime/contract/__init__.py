"""The node contract: what a node is, what a handler may do, and the words both drivers share.

Imports nothing else of twinfleet, and neither asyncio nor Zenoh.
"""

__all__ = [
    "context",
    "dispatch",
    "kinds",
    "messages",
    "names",
    "node",
    "params",
    "scene",
    "snapshot",
    "tracefile",
]
