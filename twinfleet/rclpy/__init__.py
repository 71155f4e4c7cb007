"""rclpy nodes on the node contract: the `rclpy` API node code imports (`api/`), the
engine that runs its callbacks with rclpy's executor rules, the state the checker keeps
of such a node, and the loader that makes an rclpy `Node` subclass a contract node.

Imports the contract only (and `twinfleet.interfaces` for messages); the scenario layer
imports the loader when a scenario's `class:` names an rclpy node (docs/rclpy.md).
"""

__all__ = ["adapter", "api", "current", "engine", "entities", "loader", "param_service", "refs",
           "state", "tasks", "wire"]
