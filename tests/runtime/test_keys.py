"""Key expressions: the wire format, build/parse round trips, malformed keys, and the rule that
`twinfleet/runtime/host/keys.py` is the only module that builds them."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

from twinfleet.runtime.contract.names import InvalidName
from twinfleet.runtime.host.keys import (
    ANY,
    InvalidKey,
    KeyKind,
    NodeKey,
    TopicKey,
    epoch_key,
    epoch_of,
    fleet_topics,
    kind_expr,
    node_key,
    parse_key,
    parse_node_key,
    parse_topic_key,
    topic_expr,
    topic_in_fleet,
    topic_key,
)
from twinfleet.runtime.host.transport import key_matches

PACKAGE = Path(__file__).resolve().parents[2] / "twinfleet"
KEYS_MODULE = PACKAGE / "runtime" / "host" / "keys.py"


def _built(kind: KeyKind, node: str = "r1") -> str:
    return node_key("c1a", kind, node, "/r1/scan" if kind.named else "")


# ---------------------------------------------------------------- the wire format


def test_data_keys_are_the_prefix_the_fleet_and_the_name():
    assert topic_key("c1a", "/r1/scan") == "twinfleet/c1a/r1/scan"
    assert topic_expr("*", "map") == topic_expr("*", "/map") == "twinfleet/*/map"
    assert fleet_topics("c1a") == "twinfleet/c1a/**"


@pytest.mark.parametrize(("kind", "key"), [
    (KeyKind.NODE, "twinfleet/c1a/@node/r1"),
    (KeyKind.PUB, "twinfleet/c1a/@pub/r1/r1/scan"),
    (KeyKind.SUB, "twinfleet/c1a/@sub/r1/r1/scan"),
    (KeyKind.SRV, "twinfleet/c1a/@srv/r1/r1/scan"),
    (KeyKind.EPOCH, "twinfleet/c1a/@epoch/r1"),
    (KeyKind.INFO, "twinfleet/c1a/@info/r1"),
    (KeyKind.STATS, "twinfleet/c1a/@stats/r1"),
    (KeyKind.TYPES, "twinfleet/c1a/@types/r1"),
    (KeyKind.STATE, "twinfleet/c1a/@state/r1"),
    (KeyKind.REPLAY, "twinfleet/c1a/@replay/r1"),
])
def test_node_keys_keep_their_wire_form(kind, key):
    assert _built(kind) == key


def test_kind_expressions_match_every_node_of_the_kind_and_nothing_else():
    for kind in KeyKind:
        pattern = kind_expr("c1a", kind)
        assert key_matches(pattern, _built(kind)), pattern
        assert key_matches(kind_expr(ANY, kind), _built(kind))
        others = [_built(k) for k in KeyKind if k is not kind]
        assert not any(key_matches(pattern, other) for other in others), pattern
    assert kind_expr("c1a", KeyKind.NODE) == "twinfleet/c1a/@node/*"
    assert kind_expr("c1a", KeyKind.PUB) == "twinfleet/c1a/@pub/*/**"


def test_a_fleets_data_subscription_never_sees_its_node_keys():
    assert key_matches(fleet_topics("c1a"), topic_key("c1a", "/r1/scan"))
    assert not any(key_matches(fleet_topics("c1a"), _built(kind)) for kind in KeyKind)


# ---------------------------------------------------------------- round trips


@pytest.mark.parametrize("kind", list(KeyKind))
def test_every_node_key_parses_back_to_what_built_it(kind):
    name = "/r1/scan" if kind.named else ""
    expected = NodeKey("c1a", kind, "r1", name)
    assert parse_key(_built(kind)) == expected
    assert parse_node_key(_built(kind)) == expected
    assert parse_node_key(_built(kind), kind) == expected


@pytest.mark.parametrize("topic", ["/map", "/r1/scan", "/twinfleet/shutdown", "/a/b/c/d"])
def test_every_data_key_parses_back_to_what_built_it(topic):
    assert parse_key(topic_key("c1a", topic)) == TopicKey("c1a", topic)
    assert parse_topic_key(topic_key("c1a", topic)) == TopicKey("c1a", topic)


def test_the_epoch_token_carries_the_epoch():
    assert epoch_of(epoch_key("c1a", 1_700_000_000_123_456_789)) == 1_700_000_000_123_456_789
    assert key_matches(kind_expr("c1a", KeyKind.EPOCH), epoch_key("c1a", 5))
    with pytest.raises(InvalidKey):
        epoch_of("twinfleet/c1a/@epoch/soon")
    with pytest.raises(InvalidKey):
        epoch_of(_built(KeyKind.NODE))


def test_parsed_keys_are_frozen_records():
    parsed = parse_node_key(_built(KeyKind.STATS))
    assert isinstance(parsed.kind, KeyKind)
    with pytest.raises(AttributeError):
        parsed.node = "r2"  # type: ignore[misc]


def test_topic_in_fleet_filters_by_fleet():
    key = topic_key("c1a", "/poses")
    assert topic_in_fleet("c1a", key) == TopicKey("c1a", "/poses")
    assert topic_in_fleet(ANY, key) == TopicKey("c1a", "/poses")
    assert topic_in_fleet("other", key) is None
    assert topic_in_fleet(ANY, _built(KeyKind.STATS)) is None
    assert topic_in_fleet(ANY, "elsewhere/c1a/poses") is None


# ---------------------------------------------------------------- malformed keys


@pytest.mark.parametrize("key", [
    "", "twinfleet", "twinfleet/c1a", "other/c1a/poses", "Twinfleet/c1a/poses",
    "twinfleet//poses", "twinfleet/c1a/", "twinfleet/c1a//poses", "/twinfleet/c1a/poses",
    "twinfleet/@c1a/poses", "twinfleet/c1a/poses/@node/r1",
    "twinfleet/c1a/@nope/r1", "twinfleet/c1a/@/r1", "twinfleet/c1a/@node",
    "twinfleet/c1a/@node/r1/extra", "twinfleet/c1a/@stats/r1/extra", "twinfleet/c1a/@pub/r1",
])
def test_malformed_keys_are_refused(key):
    with pytest.raises(InvalidKey):
        parse_key(key)
    assert topic_in_fleet(ANY, key) is None


def test_a_key_of_the_other_family_or_kind_is_refused():
    with pytest.raises(InvalidKey):
        parse_topic_key(_built(KeyKind.NODE))
    with pytest.raises(InvalidKey):
        parse_node_key(topic_key("c1a", "/poses"))
    with pytest.raises(InvalidKey):
        parse_node_key(_built(KeyKind.STATS), KeyKind.INFO)


def test_a_name_the_kind_does_not_take_is_refused():
    with pytest.raises(InvalidKey):
        node_key("c1a", KeyKind.PUB, "r1")  # a publication token names its topic
    with pytest.raises(InvalidKey):
        node_key("c1a", KeyKind.NODE, "r1", "/r1/scan")
    with pytest.raises(InvalidKey):
        node_key("c1a", KeyKind.SUB, "r1", "r1/scan")  # not fully qualified
    with pytest.raises(InvalidName):
        topic_key("c-1", "/poses")
    with pytest.raises(InvalidName):
        topic_key("*", "/poses")  # a wildcard is for monitors: topic_expr


def test_invalid_key_is_a_value_error():
    assert issubclass(InvalidKey, ValueError)  # callers that skip bad input catch ValueError


# ---------------------------------------------------------------- the rule


_KEY_BUILDING = re.compile(r"""KEY_PREFIX\}/|f["']twinfleet/|["']twinfleet/\{""")
_KINDS = "|".join(k.value for k in KeyKind)
_KIND_CHUNK = re.compile(rf"(^|/)@({_KINDS})(/|$)")


def _sources() -> list[Path]:
    return [p for p in sorted(PACKAGE.rglob("*.py")) if p != KEYS_MODULE]


def _code_strings(path: Path) -> list[tuple[int, str]]:
    """(line, text) of every string constant in the code, docstrings left out."""
    tree = ast.parse(path.read_text(), filename=str(path))
    docs = {id(n.value) for n in ast.walk(tree)
            if isinstance(n, ast.Expr) and isinstance(n.value, ast.Constant)}
    return [(n.lineno, n.value) for n in ast.walk(tree)
            if isinstance(n, ast.Constant) and isinstance(n.value, str) and id(n) not in docs]


def test_only_the_keys_module_builds_keys():
    found = [f"{p.relative_to(PACKAGE.parent)}:{i}: {line.strip()}"
             for p in _sources() for i, line in enumerate(p.read_text().splitlines(), 1)
             if _KEY_BUILDING.search(line) or "KEY_PREFIX" in line]
    assert found == []


def test_only_the_keys_module_spells_a_kind_chunk():
    found = [f"{p.relative_to(PACKAGE.parent)}:{line}: {text!r}"
             for p in _sources() for line, text in _code_strings(p) if _KIND_CHUNK.search(text)]
    assert found == []


def test_the_rule_catches_key_building(tmp_path):
    sample = tmp_path / "m.py"
    sample.write_text('"""Serves ``twinfleet/<fleet>/@stats/<node>``."""\n'
                      'a = f"{KEY_PREFIX}/{fleet}/x"\nb = f"twinfleet/{fleet}/x"\n'
                      'c = prefix + "/@stats/" + node\n')
    lines = sample.read_text().splitlines()
    assert [bool(_KEY_BUILDING.search(line)) for line in lines] == [False, True, True, False]
    assert [text for _, text in _code_strings(sample) if _KIND_CHUNK.search(text)] == ["/@stats/"]
