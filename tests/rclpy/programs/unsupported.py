"""A node that uses actions: not supported yet, refused at load with one line."""

from rclpy.action import ActionClient  # noqa: F401
from rclpy.node import Node


class Navigator(Node):
    def __init__(self):
        super().__init__("navigator")
