"""RIHS01 type hashes (ROS 2 REP 2011), computed from a rosbags type store.

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
"""

from __future__ import annotations

import hashlib
import json
from typing import Any

from rosbags.typesys.base import Nodetype
from rosbags.typesys.store import Typestore

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


def _field(name: str, desc: Any, referenced: list[str]) -> dict[str, Any]:
    offset, capacity = 0, 0
    if desc[0] == Nodetype.ARRAY:
        offset, capacity = ARRAY_OFFSET, desc[1][1]
        desc = desc[1][0]
    elif desc[0] == Nodetype.SEQUENCE:
        capacity = desc[1][1]
        offset = BOUNDED_SEQUENCE_OFFSET if capacity else SEQUENCE_OFFSET
        desc = desc[1][0]
    nested, string_capacity = "", 0
    if desc[0] == Nodetype.NAME:
        type_id, nested = NESTED_ID, desc[1]
        referenced.append(nested)
    else:
        base, bound = desc[1]
        if base == "string" and bound:
            type_id, string_capacity = BOUNDED_STRING_ID, bound
        else:
            type_id = PRIMITIVE_IDS[base]
    return {"name": name, "type": {"type_id": type_id + offset, "capacity": capacity,
                                   "string_capacity": string_capacity,
                                   "nested_type_name": nested}}


def _struct(store: Typestore, name: str, referenced: list[str]) -> dict[str, Any]:
    fields = store.fielddefs[name][1] or [(EMPTY_MEMBER, (Nodetype.BASE, ("uint8", 0)))]
    return {"type_name": name,
            "fields": [_field(fname, desc, referenced) for fname, desc in fields]}


def type_description(store: Typestore, name: str) -> dict[str, Any]:
    """The hashed description of `name`: itself and every type it references, sorted.

    Raises:
        KeyError: `name` or a type it references is not in `store`.
    """
    todo: list[str] = []
    main = _struct(store, name, todo)
    found: dict[str, dict[str, Any]] = {}
    while todo:
        nested = todo.pop()
        if nested != name and nested not in found:
            found[nested] = _struct(store, nested, todo)
    return {"type_description": main,
            "referenced_type_descriptions": [found[k] for k in sorted(found)]}


def rihs01(store: Typestore, name: str) -> str:
    """``RIHS01_<sha256 hex>`` of `name` as rosidl computes it (module docstring)."""
    text = json.dumps(type_description(store, name))
    return "RIHS01_" + hashlib.sha256(text.encode()).hexdigest()
