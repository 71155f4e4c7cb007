"""Movement arithmetic of the robot (docs/robots.md §5).

All times are integer milliseconds, rounded by the profile's rule
(``round_m`` for the model, which adds one on exact integers).
"""

from __future__ import annotations

import math

from twinfleet.nodes.grid import SQRT2, Cell, octile
from twinfleet.nodes.profile import Profile


def hop_time_ms(speed_mps: float, diagonal: bool, res: float, profile: Profile) -> int:
    """Time of one hop: round(1000·R/v), or round(1000·SQRT2·R/v) diagonally.

    Raises:
        ValueError: speed not positive.
    """
    if not speed_mps > 0:
        raise ValueError(f"speed must be positive, got {speed_mps}")
    dist = 1000 * SQRT2 * res if diagonal else 1000 * res
    return profile.round(dist / speed_mps)


def rotation_time_ms(
    from_dir: int, to_dir: int, profile: Profile, angular_dps: float = 360.0
) -> int:
    """Time to turn between two headings.

    The model turns by |Δdir| without wrap-around (7→0 costs 7 steps);
    the fixed profile takes the shorter way round.

    Args:
        from_dir: current heading 0..7.
        to_dir: new heading 0..7.
        profile: ``rotation`` switch and rounding.
        angular_dps: angular speed in degrees per second.
    """
    k = abs(to_dir - from_dir)
    if profile.rotation == "shortest":
        k = min(k % 8, 8 - k % 8)
    return profile.round(1000 * 45 * k / angular_dps)


def cells_per_second(speed_mps: float, res: float, profile: Profile) -> int:
    """The model's ``default_velocity``: round(v/R) cells per second."""
    return profile.round(speed_mps / res)


def max_waiting_rounds(maxwait_ms: int, scan_ms: int, profile: Profile) -> int:
    """Blocked evaluations before a back-off: round(maxwait/scan period) (docs/robots.md §6)."""
    if scan_ms <= 0:
        raise ValueError(f"scan period must be positive, got {scan_ms}")
    return profile.round(maxwait_ms / scan_ms)


def distance_to_target(cell: Cell, target: Cell, profile: Profile) -> int:
    """The model's ``distance2target``: round(octile distance in cells)."""
    return profile.round(octile(cell, target))


def within_tolerance(cell: Cell, target: Cell, tolerance: int, profile: Profile) -> bool:
    """True if ``distance_to_target`` ≤ ``tolerance`` (model: tolerance 2 = Chebyshev ≤ 1)."""
    return distance_to_target(cell, target, profile) <= tolerance


def check_scan_rate_rule(speed_mps: float, res: float, scan_ms: int, profile: Profile) -> str | None:
    """Paper Eq. 1: the time of one (edge) hop must exceed two scan periods.

    Returns:
        None if the rule holds, else a message naming the numbers and the speed limit.
    """
    hop = hop_time_ms(speed_mps, False, res, profile)
    if hop > 2 * scan_ms:
        return None
    limit = res / (2 * scan_ms / 1000)
    return (
        f"speed {speed_mps} m/s breaks the scan-rate rule (Eq. 1): hop time {hop} ms "
        f"is not greater than 2 x scan period {scan_ms} ms; keep the speed below {limit:.4g} m/s"
    )


def check_cell_size_rule(res: float, robot_length: float) -> str | None:
    """Paper Eq. 2: CELL_WIDTH < ROBOT_LENGTH/√2, so consecutive hop poses overlap.

    Returns:
        None if the rule holds, else a message.
    """
    bound = robot_length / math.sqrt(2)
    if res < bound:
        return None
    return f"cell size {res} m breaks Eq. 2: must be below robot length / sqrt(2) = {bound:.4g} m"
