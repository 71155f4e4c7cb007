"""Every Zenoh key expression of a fleet, built and parsed here and nowhere else.

Two families of keys share the prefix ``twinfleet/<fleet>``:

* **data keys** ``twinfleet/<fleet>/<topic path>``: the samples of topic (or the
  queries of service) ``/<topic path>``, a fully qualified name
  (`runtime.contract.names.resolve`). `topic_key` builds them, `fleet_topics`
  matches every one of a fleet, `TopicKey` is what parsing one gives.
* **node keys** ``twinfleet/<fleet>/@<kind>/<node>``, one `KeyKind` each: a
  process's liveliness tokens and queryables, and the launcher's epoch token::

    twinfleet/<fleet>/@node/<node>                 token: one per running node
    twinfleet/<fleet>/@pub/<node>/<topic path>     token: node publishes on /<topic path>
    twinfleet/<fleet>/@sub/<node>/<topic path>     token: node subscribes to /<topic path>
    twinfleet/<fleet>/@srv/<node>/<service path>   token: node serves /<service path>
    twinfleet/<fleet>/@epoch/<epoch ns>            token: the launcher's fleet time 0
    twinfleet/<fleet>/@info/<node>                 queryable: the node describes itself
    twinfleet/<fleet>/@stats/<node>                queryable: the host's counters
    twinfleet/<fleet>/@types/<node>                queryable: JSON Schemas of its messages
    twinfleet/<fleet>/@state/<node>                publication: state reports to the launcher
    twinfleet/<fleet>/@replay/<node>               queryable: a gated node's replay gate
    twinfleet/<fleet>/@fleet/<server>              queryable: the fleet described (scene,
                                                   latched topics) by its launcher or player

  `node_key` builds them, `kind_expr` matches every key of one kind, `NodeKey`
  is what parsing one gives.

`@` chunks are verbatim in Zenoh: ``*`` and ``**`` never match them, so
``twinfleet/<fleet>/**`` (a data subscriber) never sees a node key, and a topic
name, whose components are tokens (`runtime.contract.names.validate_token`),
never holds one. That is how `parse_key` tells the two families apart.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from twinfleet.runtime.contract.names import validate_token

KEY_PREFIX = "twinfleet"
ANY = "*"  # a whole-chunk wildcard: every fleet, or every node


class InvalidKey(ValueError):
    """A key expression that is not one of a fleet's keys, or a key that cannot be built."""


class KeyKind(enum.Enum):
    """The ``@<kind>`` chunk of a node key (module docstring)."""

    NODE = "node"
    PUB = "pub"
    SUB = "sub"
    SRV = "srv"
    EPOCH = "epoch"
    INFO = "info"
    STATS = "stats"
    TYPES = "types"
    STATE = "state"
    REPLAY = "replay"
    FLEET = "fleet"

    @property
    def named(self) -> bool:
        """Whether keys of this kind end with a topic or service name after the node."""
        return self in _NAMED


_NAMED = frozenset({KeyKind.PUB, KeyKind.SUB, KeyKind.SRV})


@dataclass(frozen=True, slots=True)
class TopicKey:
    """A parsed data key: `topic` is a fully qualified name (``/r1/scan``)."""

    fleet: str
    topic: str


@dataclass(frozen=True, slots=True)
class NodeKey:
    """A parsed node key. `node` is the chunk after the kind (the epoch, in ns, for
    `KeyKind.EPOCH`); `name` the topic or service of a named kind, else ''."""

    fleet: str
    kind: KeyKind
    node: str
    name: str = ""


# ---------------------------------------------------------------- building


def topic_key(fleet: str, fq_name: str) -> str:
    """Data key of fully qualified name `fq_name` in `fleet` (a valid name, not a wildcard).

    Raises:
        InvalidName: `fleet` is not a valid name component.
    """
    validate_token(fleet, "fleet")
    return f"{KEY_PREFIX}/{fleet}{fq_name}"


def topic_expr(fleet: str, name: str) -> str:
    """Key expression of topic or service `name` in `fleet`, as a monitor asks for it:
    `fleet` may be ``*``, and a name without its leading ``/`` is taken as absolute."""
    return f"{KEY_PREFIX}/{fleet}{name if name.startswith('/') else '/' + name}"


def fleet_topics(fleet: str) -> str:
    """Key expression matching every data key of `fleet` (``*``: of every fleet)."""
    return f"{KEY_PREFIX}/{fleet}/**"


def node_key(fleet: str, kind: KeyKind, node: str, name: str = "") -> str:
    """Node key of `kind` for `node` in `fleet`; `name` (fully qualified) for a named kind.

    `fleet` or `node` may be ``*`` for a key expression; `kind_expr` matches a whole kind.

    Raises:
        InvalidKey: a named kind without a name, or a name for a kind that has none.
    """
    if kind.named != bool(name) or (name and not name.startswith("/")):
        need = "a fully qualified name" if kind.named else "no name"
        raise InvalidKey(f"a @{kind.value} key takes {need}, got {name!r}")
    return f"{KEY_PREFIX}/{fleet}/@{kind.value}/{node}{name}"


def kind_expr(fleet: str, kind: KeyKind) -> str:
    """Key expression matching every node key of `kind` in `fleet` (``*``: every fleet)."""
    return f"{KEY_PREFIX}/{fleet}/@{kind.value}/{ANY}" + ("/**" if kind.named else "")


def fleet_key(fleet: str, server: str = "launcher") -> str:
    """The queryable through which the process that runs a fleet (`server`: the launcher,
    or the player of a recording) describes it (`runtime.host.introspect.fleet_description`)."""
    return node_key(fleet, KeyKind.FLEET, server)


def epoch_key(fleet: str, epoch_ns: int) -> str:
    """The launcher's epoch token: fleet time 0 of `fleet` is `epoch_ns` (`time.time_ns()`)."""
    return node_key(fleet, KeyKind.EPOCH, str(epoch_ns))


# ---------------------------------------------------------------- parsing


def parse_key(key: str) -> TopicKey | NodeKey:
    """The data key or node key that concrete key `key` is.

    Raises:
        InvalidKey: not ``twinfleet/<fleet>/...``, an empty chunk, an unknown kind, or a
            node key with a missing or surplus name.
    """
    parts = key.split("/")
    if len(parts) < 3 or parts[0] != KEY_PREFIX or "" in parts or parts[1].startswith("@"):
        raise InvalidKey(f"not a {KEY_PREFIX} key: {key!r}")
    if not parts[2].startswith("@"):
        if any(p.startswith("@") for p in parts[3:]):
            raise InvalidKey(f"an @ chunk inside a topic name: {key!r}")
        return TopicKey(parts[1], "/" + "/".join(parts[2:]))
    return _node_key(key, parts)


def _node_key(key: str, parts: list[str]) -> NodeKey:
    try:
        kind = KeyKind(parts[2][1:])
    except ValueError:
        raise InvalidKey(f"unknown kind {parts[2]!r} in {key!r}") from None
    if len(parts) < 4 or kind.named != (len(parts) > 4):
        raise InvalidKey(f"a @{kind.value} key is .../@{kind.value}/<node>"
                         + ("/<name>" if kind.named else "") + f", got {key!r}")
    name = "/" + "/".join(parts[4:]) if kind.named else ""
    return NodeKey(parts[1], kind, parts[3], name)


def parse_topic_key(key: str) -> TopicKey:
    """`parse_key` of a data key.

    Raises:
        InvalidKey: `key` is not a data key.
    """
    parsed = parse_key(key)
    if not isinstance(parsed, TopicKey):
        raise InvalidKey(f"not a data key: {key!r}")
    return parsed


def parse_node_key(key: str, kind: KeyKind | None = None) -> NodeKey:
    """`parse_key` of a node key (of `kind`, if given).

    Raises:
        InvalidKey: `key` is not a node key, or not of `kind`.
    """
    parsed = parse_key(key)
    if not isinstance(parsed, NodeKey) or (kind is not None and parsed.kind is not kind):
        raise InvalidKey(f"not a @{kind.value if kind else '<kind>'} key: {key!r}")
    return parsed


def topic_in_fleet(wanted: str, key: str) -> TopicKey | None:
    """The data key `key` if it is one of fleet `wanted` (``*``: of any fleet), else None."""
    try:
        parsed = parse_topic_key(key)
    except InvalidKey:
        return None
    return parsed if wanted in (ANY, parsed.fleet) else None


def epoch_of(key: str) -> int:
    """The epoch (ns) an epoch token (`epoch_key`) announces.

    Raises:
        InvalidKey: `key` is not an epoch token.
    """
    node = parse_node_key(key, KeyKind.EPOCH).node
    if not node.isdigit():
        raise InvalidKey(f"not an epoch in ns: {key!r}")
    return int(node)
