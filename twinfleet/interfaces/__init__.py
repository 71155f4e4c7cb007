"""ROS 2 message and service types, generated from the field's own definitions (docs/rclpy.md).

A layer above the contract: it imports the contract's message layer and rosbags,
nothing else of twinfleet. The rclpy-compatible API (`twinfleet.rclpy`) and the
ROS 2 bridge (`twinfleet.ros2`) import it.

Modules: `definitions` (where definitions come from: installed ``share/<pkg>``
folders, rosbags' Jazzy store; value types), `typehash` (RIHS01, the one
implementation), `values` (field defaults, checks, freeze/thaw of one field),
`generate` (the mutable classes, their frozen contract twins, `load_interface`),
`guard` (a user type that borrows a standard package's name with other fields).

Public API: `load_interface(package, kind)` → a module-like namespace
(``std_msgs.msg``), `freeze(msg)` → the frozen contract message, `thaw(frozen)`
→ a new mutable message, `message_type(ros_type)`, `service_type(ros_type)`,
`contract_type(ros_type)` (the frozen class, for native nodes),
`from_fields(ros_type, mapping)`, `InterfaceError`, `FieldValueError`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from twinfleet.runtime.contract.lazy import lazy_names

if TYPE_CHECKING:
    from twinfleet.interfaces.definitions import InterfaceError
    from twinfleet.interfaces.generate import (
        RosMessage,
        contract_name,
        contract_type,
        freeze,
        from_fields,
        load_interface,
        message_type,
        service_type,
        thaw,
    )
    from twinfleet.interfaces.values import FieldValueError

# Each public name's module, imported on first use: every command imports the package for
# `guard`, which needs `definitions` only (and then only for a user's types), while
# `generate` and what it imports are a twentieth of what `check` compiles.
_HOMES = {"InterfaceError": "definitions", "FieldValueError": "values",
          **dict.fromkeys(("RosMessage", "contract_name", "contract_type", "freeze",
                           "from_fields", "load_interface", "message_type", "service_type",
                           "thaw"), "generate")}

__getattr__ = lazy_names(__name__, _HOMES)

__all__ = ["FieldValueError", "InterfaceError", "RosMessage", "contract_name", "contract_type",
           "freeze", "from_fields", "load_interface", "message_type", "service_type", "thaw"]
