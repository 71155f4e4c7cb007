"""RIHS01 type hashes (ROS 2 REP 2011), computed from definitions (`definitions.Definition`).

A hash is ``RIHS01_`` + the SHA-256 of a JSON text that describes the type: the
type itself, then every type it references, directly or not, sorted by name;
each as its name and its fields, a field as its name and its type (a type id,
the array or bound capacity, the string bound, the nested type's name). Default
values and comments are not hashed. The JSON is Python's `json.dumps` with its
default separators (``", "`` and ``": "``), as rosidl writes it.

Where rosbags is wrong: a ``char`` field of a ``.msg`` file. rosidl turns
``.msg`` into IDL first, and there ``char`` becomes ``uint8``, so rosidl
hashes it with type id 3 (``std_msgs/msg/Char``'s field has type id 3 in
its generated ``Char.json``). rosbags' `Typestore.hash_rihs01` writes type id
13 (IDL's own ``char``) and so gives ``std_msgs/msg/Char``, and every type with
a char field, a hash no ROS 2 node announces. This module maps ``char`` to
``uint8`` for that reason (tests/ros2/test_typehash.py checks both hashes against
rosidl's).

The one implementation: the generated message classes (`interfaces.generate`) and
the ROS 2 bridge's type store (`twinfleet.ros2.cdr`, through `store_lookup`) both
hash here.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable
from typing import Any

from twinfleet.interfaces.definitions import Container, Definition, FieldDef, FieldType, from_store

Lookup = Callable[[str], Definition]

#: type_description_interfaces/msg/FieldType ids of the primitive types a .msg can name
PRIMITIVE_IDS = {
    "int8": 2, "uint8": 3, "int16": 4, "uint16": 5, "int32": 6, "uint32": 7,
    "int64": 8, "uint64": 9, "float32": 10, "float64": 11, "float128": 12,
    "char": 3,  # a .msg char is IDL uint8 (module docstring)
    "bool": 15, "byte": 16, "string": 17,
}
NESTED_ID = 1
BOUNDED_STRING_ID = 21
ARRAY_OFFSET, BOUNDED_SEQUENCE_OFFSET, SEQUENCE_OFFSET = 48, 96, 144
EMPTY_MEMBER = "structure_needs_at_least_one_member"  # rosidl's member of an empty message
_EMPTY = (FieldDef(EMPTY_MEMBER, FieldType("uint8")),)


def _field(f: FieldDef, referenced: list[str]) -> dict[str, Any]:
    t = f.type
    offset, capacity = 0, 0
    if t.container is Container.ARRAY:
        offset, capacity = ARRAY_OFFSET, t.size
    elif t.container is Container.SEQUENCE:
        capacity = t.size
        offset = BOUNDED_SEQUENCE_OFFSET if capacity else SEQUENCE_OFFSET
    nested, string_capacity = "", 0
    if t.nested:
        type_id, nested = NESTED_ID, t.base
        referenced.append(nested)
    elif t.base == "string" and t.string_bound:
        type_id, string_capacity = BOUNDED_STRING_ID, t.string_bound
    else:
        type_id = PRIMITIVE_IDS[t.base]
    return {"name": f.name, "type": {"type_id": type_id + offset, "capacity": capacity,
                                     "string_capacity": string_capacity,
                                     "nested_type_name": nested}}


def _struct(definition: Definition, referenced: list[str]) -> dict[str, Any]:
    return {"type_name": definition.name,
            "fields": [_field(f, referenced) for f in definition.fields or _EMPTY]}


def type_description(name: str, lookup: Lookup) -> dict[str, Any]:
    """The hashed description of `name`: itself and every type it references, sorted.

    Raises:
        KeyError or InterfaceError (from `lookup`): a type that is not known.
    """
    todo: list[str] = []
    main = _struct(lookup(name), todo)
    found: dict[str, dict[str, Any]] = {}
    while todo:
        nested = todo.pop()
        if nested != name and nested not in found:
            found[nested] = _struct(lookup(nested), todo)
    return {"type_description": main,
            "referenced_type_descriptions": [found[k] for k in sorted(found)]}


def rihs01(name: str, lookup: Lookup) -> str:
    """``RIHS01_<sha256 hex>`` of `name` as rosidl computes it (module docstring)."""
    text = json.dumps(type_description(name, lookup))
    return "RIHS01_" + hashlib.sha256(text.encode()).hexdigest()


def store_lookup(store: Any) -> Lookup:
    """A lookup over a rosbags `Typestore` (its ``fielddefs``: name → (constants, fields))."""
    return lambda name: from_store(name, store.fielddefs[name])
