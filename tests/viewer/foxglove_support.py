"""Decoding Foxglove messages with the schemas that came with them (a protobuf
FileDescriptorSet), as a Foxglove client does: no foxglove-sdk classes involved."""

from __future__ import annotations

import functools
from typing import Any


@functools.lru_cache(maxsize=64)
def _message_class(name: str, schema: bytes) -> Any:
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

    files = descriptor_pb2.FileDescriptorSet.FromString(schema)
    pool = descriptor_pool.DescriptorPool()
    pending = list(files.file)
    while pending:  # add each file after its dependencies
        progress = False
        for f in list(pending):
            try:
                pool.Add(f)
            except TypeError:
                continue
            pending.remove(f)
            progress = True
        if not progress:
            raise ValueError(f"cannot resolve the descriptors of {name}")
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(name))


def decode_protobuf(name: str, schema: bytes, payload: bytes) -> Any:
    """Decode `payload` as message `name` of the FileDescriptorSet `schema`."""
    return _message_class(name, bytes(schema)).FromString(bytes(payload))
