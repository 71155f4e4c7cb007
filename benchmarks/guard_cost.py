"""What the input guard (runtime.core.guard) costs per sample, against decoding it.

Prints JSON: microseconds per operation for a RobotPose and an ObstacleScan
envelope — `decode_fields` (the baseline every sample pays), signing,
verifying the signature, and the type/field admission — and each as a ratio
of the decode. In-process, no Zenoh: the guard's share of a delivery.

    python3 benchmarks/guard_cost.py [--seconds S]
"""

from __future__ import annotations

import argparse
import json
import sys
import timeit
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # this checkout's twinfleet

from twinfleet.nodes.msgs import ObstacleScan, RobotPose  # noqa: E402
from twinfleet.runtime.contract.messages import decode_fields, encode  # noqa: E402
from twinfleet.runtime.core.guard import Admission, authentic, new_key, sign  # noqa: E402


def per_op_us(fn, seconds: float) -> float:
    """Best of five runs of `fn`, each about `seconds` / 5 long, in µs per call."""
    timer = timeit.Timer(fn)
    number, _ = timer.autorange()
    runs = timer.repeat(repeat=5, number=max(1, int(number * seconds / 5 / 0.2)))
    return min(runs) / max(1, int(number * seconds / 5 / 0.2)) * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=2.0, help="time per figure")
    args = parser.parse_args()
    key, where = new_key(), "twinfleet/c1a/poses"
    samples = {"RobotPose": RobotPose("r1", (31, 23), 1, 2),
               "ObstacleScan": ObstacleScan("r1", tuple((i, i + 1) for i in range(16)))}
    out = {}
    for name, msg in samples.items():
        payload = encode(msg, stamp_ms=1, seq=1, sender="r1")
        tag = sign(key, where, payload)
        admit, decoded = Admission(type(msg)), decode_fields(payload)[0]
        figures = {"decode": per_op_us(lambda p=payload: decode_fields(p), args.seconds),
                   "sign": per_op_us(lambda p=payload: sign(key, where, p), args.seconds),
                   "verify": per_op_us(lambda p=payload, t=tag: authentic(key, where, p, t),
                                       args.seconds),
                   "admit": per_op_us(lambda m=decoded, a=admit: a(m), args.seconds)}
        base = figures["decode"]
        out[name] = {"bytes": len(payload), **{f"{k}_us": round(v, 2) for k, v in figures.items()},
                     **{f"{k}_vs_decode": round(v / base, 2) for k, v in figures.items()
                        if k != "decode"}}
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
