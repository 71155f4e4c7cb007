"""The grid of a sweep: `--param` words parsed into axes, axes into points."""

from __future__ import annotations

import pytest

from twinfleet.sweep.grid import (
    MAX_POINTS,
    GridError,
    Target,
    format_value,
    parse_axis,
    parse_grid,
    parse_values,
    point_label,
    points,
)

pytestmark = pytest.mark.timeout(30)


def test_a_list_of_yaml_values_keeps_types_and_brackets():
    assert parse_values("0.4,0.6,1") == (0.4, 0.6, 1)
    assert parse_values("[5, 5],[6, 6]") == ([5, 5], [6, 6])
    assert parse_values("true,false") == (True, False)
    assert parse_values("fixed, rebeca") == ("fixed", "rebeca")


def test_a_range_is_inclusive_and_printable():
    assert parse_values("60:140:40") == (60, 100, 140)
    assert parse_values("0.3:0.9:0.2") == (0.3, 0.5, 0.7, 0.9)
    assert parse_values("0.1:0.35:0.1") == (0.1, 0.2, 0.3)  # stop not on a step: left out
    assert all(isinstance(v, int) for v in parse_values("1:5:2"))


@pytest.mark.parametrize(("word", "target", "node", "key"), [
    ("r1.speed=0.4", Target.NODE, "r1", "speed"),
    ("r1.speed:=0.4", Target.NODE, "r1", "speed"),
    ("scan_rate_ms=100", Target.COMMON, None, "scan_rate_ms"),
    ("*.speed=0.4", Target.EVERY_NODE, None, "speed"),
    ("profile=fixed", Target.COMMON, None, "profile"),  # a parameter of the robots, no option
    ("semantics=ros,rebeca", Target.SEMANTICS, None, "semantics"),
    ("check.max_states=100", Target.CHECK, None, "max_states"),
])
def test_a_name_says_what_it_sets(word, target, node, key):
    axis = parse_axis(word)
    assert (axis.target, axis.node, axis.key) == (target, node, key)


def test_points_are_every_combination_the_last_axis_fastest():
    axes = parse_grid(["r1.speed=0.4,0.6", "scan_rate_ms=60:100:40"])
    grid = points(axes)
    assert grid == [(("r1.speed", 0.4), ("scan_rate_ms", 60)),
                    (("r1.speed", 0.4), ("scan_rate_ms", 100)),
                    (("r1.speed", 0.6), ("scan_rate_ms", 60)),
                    (("r1.speed", 0.6), ("scan_rate_ms", 100))]
    assert point_label(grid[1]) == "r1.speed=0.4 scan_rate_ms=100"
    assert format_value([5, 5]) == "[5, 5]"


@pytest.mark.parametrize(("words", "message"), [
    (["r1.speed"], "--param 'r1.speed': expected [NODE.|*.|check.]NAME=VALUES"),
    (["r1 speed=0.4"], "expected [NODE.|*.|check.]NAME=VALUES"),
    (["r1.speed="], "--param 'r1.speed=': no values"),
    (["r1.speed=0.4,,0.6"], "an empty value in '0.4,,0.6'"),
    (["r1.speed=0.4,0.4"], "a value is listed twice"),
    (["r1.speed=0.9:0.3:0.2"], "a range start:stop:step needs start <= stop and step > 0"),
    (["r1.speed=0.3:0.9:0"], "a range start:stop:step needs start <= stop and step > 0"),
    (["r1.speed=[1, 2"], "is not YAML"),
    (["semantics=dds"], "semantics is one of ros, rebeca"),
    (["r1.speed=0.4", "r1.speed=0.6"], "--param r1.speed given twice"),
    ([], "give at least one --param NAME=VALUES"),
    (["a=0:20000:1"], f"20,001 values (at most {MAX_POINTS:,})"),
    (["a=0:99:1", "b=0:199:1"], f"the grid has 20,000 points (at most {MAX_POINTS:,})"),
])
def test_bad_words_are_one_line_naming_them(words, message):
    with pytest.raises(GridError) as caught:
        parse_grid(words)
    text = str(caught.value)
    assert message in text and "\n" not in text, text
