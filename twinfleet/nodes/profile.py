"""Behaviour profiles: every switch between the paper's model and the intended behaviour.

`Profile` has one attribute per knob (docs/robots.md §9). ``REBECA`` reproduces the Timed
Rebeca model bit for bit where that matters; ``FIXED`` is the corrected, intended
behaviour and the default.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal


@dataclass(frozen=True, slots=True)
class Profile:
    """All behaviour switches of the robot system.

    Attributes:
        name: profile name as written in scenario files.
        round_model: True = the model's ``round_m`` (trunc + sign, +1 on integers);
            False = round half away from zero.
        planner_neighbours: 7 (the model's A*, no SE) or 8.
        planner_relax: False = first discovery wins (model); True = standard A*
            with decrease-key.
        inflation: ``"one_pass"`` (the model's in-place dilation, which keeps only
            marks towards lower rows and columns) or ``"full"`` (8-neighbour dilation).
        occupancy: ``"gray204"`` (occupied iff gray < 204) or ``"ros_trinary"``
            (ROS map_server thresholds from the YAML, unknown counts as occupied).
        scan_mode: ``"model"`` (the model's scan exactly, docs/robots.md §4) or ``"exact"``
            (centre origin, -90..+90 every increment, exact trig).
        collision: ``"corner_box"`` (strict two-corner box test, docs/robots.md §7) or
            ``"sat"`` (exact oriented rectangles with margin).
        rotation: ``"model"`` (125·|Δ|+1, no wrap) or ``"shortest"``.
        validate_backoff: drop back-off candidates whose target is off-map or blocked.
        track_front_obstacle: keep the model's informational ``front_obstacle`` (free hops
            ahead, set on every scan and every hop-or-wait decision) in the robot state.
            Nothing reads it, but it is a state variable of the model, so RMC tells
            apart states that differ only in it; the fixed profile leaves it at 0.
        robot_aware_stop: the stop check widens its lateral band for scanned cells
            that are not static obstacles (other robots) to a whole robot width, so
            robots in the neighbouring lane stop instead of brushing past (the
            model's point-sized band lets diagonal neighbours overlap).
        report_arrival_pose: a robot that arrives publishes its (stopped) pose before
            its "arrived" status; the model never reports arriving (docs/robots.md §5).
        collide_unheard: the map server's collision test includes robots it has not
            heard from yet, at the unknown cell, as the model does (docs/robots.md §7); the fixed
            profile skips them.
    """

    name: str
    round_model: bool
    planner_neighbours: Literal[7, 8]
    planner_relax: bool
    inflation: Literal["one_pass", "full"]
    occupancy: Literal["gray204", "ros_trinary"]
    scan_mode: Literal["model", "exact"]
    collision: Literal["corner_box", "sat"]
    rotation: Literal["model", "shortest"]
    validate_backoff: bool
    track_front_obstacle: bool
    robot_aware_stop: bool
    report_arrival_pose: bool
    collide_unheard: bool

    def round(self, x: float) -> int:
        """Round ``x`` to an int by this profile's rule.

        Args:
            x: the value.

        Returns:
            ``round_m(x)`` for the model, else round half away from zero.
        """
        return round_m(x) if self.round_model else round_half_away(x)


def round_m(x: float) -> int:
    """The model's rounding: ``trunc(x) + sign(x)`` (round_m(2.0) == 3, round_m(0) == 0)."""
    t = math.trunc(x)
    return t + (1 if x > 0 else -1 if x < 0 else 0)


def round_half_away(x: float) -> int:
    """Ordinary rounding, halves away from zero (Python's ``round`` is banker's)."""
    r = math.floor(abs(x) + 0.5)
    return r if x >= 0 else -r


REBECA = Profile(
    name="rebeca",
    round_model=True,
    planner_neighbours=7,
    planner_relax=False,
    inflation="one_pass",
    occupancy="gray204",
    scan_mode="model",
    collision="corner_box",
    rotation="model",
    validate_backoff=False,
    track_front_obstacle=True,
    robot_aware_stop=False,
    report_arrival_pose=False,
    collide_unheard=True,
)

FIXED = Profile(
    name="fixed",
    round_model=False,
    planner_neighbours=8,
    planner_relax=True,
    inflation="full",
    occupancy="ros_trinary",
    scan_mode="exact",
    collision="sat",
    rotation="shortest",
    validate_backoff=True,
    track_front_obstacle=False,
    robot_aware_stop=True,
    report_arrival_pose=True,
    collide_unheard=False,
)

PROFILES: dict[str, Profile] = {p.name: p for p in (FIXED, REBECA)}


def profile_named(name: str) -> Profile:
    """Look a profile up by name.

    Args:
        name: ``"fixed"`` or ``"rebeca"``.

    Returns:
        The profile.

    Raises:
        ValueError: unknown name; the message lists the valid names.
    """
    try:
        return PROFILES[name]
    except KeyError:
        valid = ", ".join(sorted(PROFILES))
        raise ValueError(f"unknown profile {name!r}; valid names: {valid}") from None
