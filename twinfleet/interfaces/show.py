"""`interface show` of a standard ROS 2 type: its definition as ``ros2 interface show`` prints it.

Each field as ``type name`` (with its default, if any), constants first; a nested
type's fields follow it, indented by one tab per level; a service's request, ``---``,
its response. The first line names the type and where its definition was read.
"""

from __future__ import annotations

from twinfleet.interfaces.definitions import (
    Definition,
    InterfaceError,
    message_definition,
    ros_name,
    service_definitions,
)


def definition_text(type_name: str) -> str | None:
    """The text `interface show` prints for `type_name` (``pkg/msg/Name``, ``pkg/srv/Name``,
    or the contract's ``pkg/Name``), or None when it names no ROS 2 type with a definition."""
    parts = type_name.split("/")
    try:
        if len(parts) == 3 and parts[1] == "srv" and not parts[2].endswith(
                ("_Request", "_Response")):
            request, response = service_definitions(type_name)
            return (f"# {type_name} ({request.source})\n" + _body(request, 0) + "---\n"
                    + _body(response, 0))
        ros_type = ros_name(type_name)
        if ros_type is None:
            return None
        definition = message_definition(ros_type)
    except InterfaceError:
        return None
    return f"# {definition.name} ({definition.source})\n" + _body(definition, 0)


def _body(definition: Definition, depth: int) -> str:
    indent = "\t" * depth
    lines = [f"{indent}{c.base} {c.name}={c.value!r}" for c in definition.constants]
    for f in definition.fields:
        default = "" if f.default is None else f" {f.default!r}"
        lines.append(f"{indent}{f.type.msg()} {f.name}{default}")
        if f.type.nested:
            lines.append(_body(message_definition(f.type.base), depth + 1).rstrip("\n"))
    return "".join(f"{line}\n" for line in lines if line)
