"""Name resolution as in ROS 2: relative names live in the node's namespace.

`resolve("scan", "/r2")` is `/r2/scan`; `resolve("/map", "/r2")` is `/map`;
`resolve("~/status", "/r2", "r2")` is `/r2/r2/status`. Pure functions: both the
live host and the checker use them. A name's Zenoh key expression is a
transport concern, built by the host (`runtime.host.keys.topic_key`).
"""

from __future__ import annotations

import functools
import re

_TOKEN = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")

#: The sender an operator's command (`twinfleet topic pub`, `service call`) writes into the
#: envelopes it sends: a node tells input from outside the fleet by it (`NodeStatistics.
#: rejected_external`), and a live verdict names such input instead of blaming the fleet.
OPERATOR_SENDER = "twinfleet-cli"
#: The sender the ROS 2 bridge writes into what it forwards into a fleet (its inbound routes).
BRIDGE_SENDER = "ros2_bridge"


class InvalidName(ValueError):
    """A topic, service, node or namespace name breaks the naming rules."""


def validate_token(token: str, what: str = "name") -> None:
    """Check one path component: letters, digits, underscore; no leading digit, no `__`."""
    if not _TOKEN.match(token) or "__" in token:
        raise InvalidName(
            f"invalid {what} component {token!r}: use letters, digits and '_', "
            "not starting with a digit, without '__'"
        )


def normalise_namespace(namespace: str | None) -> str:
    """Return a namespace as '/a/b' ('' for the root namespace)."""
    if not namespace or namespace == "/":
        return ""
    ns = "/" + namespace.strip("/")
    for part in ns[1:].split("/"):
        validate_token(part, "namespace")
    return ns


@functools.lru_cache(maxsize=4096)  # pure, and on the publish hot path
def resolve(name: str, namespace: str | None = "", node_name: str | None = None) -> str:
    """Return the fully qualified name of `name` seen from a node in `namespace`."""
    if not name or name.endswith("/"):
        raise InvalidName(f"invalid name {name!r}: empty or ending with '/'")
    ns = normalise_namespace(namespace)
    if name.startswith("~"):
        if node_name is None:
            raise InvalidName(f"private name {name!r} needs a node name")
        rest = name[1:].lstrip("/")
        full = f"{ns}/{node_name}" + (f"/{rest}" if rest else "")
    elif name.startswith("/"):
        full = name
    else:
        full = f"{ns}/{name}"
    for part in full[1:].split("/"):
        validate_token(part, "name")
    return full

