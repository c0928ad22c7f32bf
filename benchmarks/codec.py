"""Cost of the codec per message: encode, decode, and both, for the messages of one lockstep step.

    python benchmarks/codec.py [--repeats 7] [--number 20000] [--json out.json]

Each cell is the median over `repeats` timings of `number` calls, in microseconds per call. A 4-joint
step moves 15 messages (4 obs, 1 task, 3 down, 3 up, 4 cmd), so "step" = 4 obs + task + 3 down + 3 up
+ 4 cmd, each encoded once and decoded once (the columns weighted by that mix). "mac" is the MAC's share
of encode+decode (sign, then hash again and compare as decode does), measured alone in the same sitting,
so the unsigned cost is the difference even when the machine is noisy.
"""

from __future__ import annotations

import argparse
import hmac
import json
import statistics
import timeit
from pathlib import Path
from typing import Any

from kinswarm.protocol import codec
from kinswarm.protocol.messages import Cmd, Down, Obs, Task, Up

KEY = b"0123456789abcdef0123456789abcdef"
RUN = "chain4-bench"
TIPS = {"a4": (1.2345678, 2.3456789, 0.4567891)}
SAMPLES: dict[str, tuple[Any, int]] = {  # message, how many per 4-joint step
    "obs": (Obs(epoch=3, step=123, q=0.52359877), 4),
    "task": (Task(epoch=3, step=123, goal=(4.16, 6.18), tips=TIPS), 1),
    "down": (Down(epoch=3, step=123, base=(1.0, 2.0, 0.5), goal=(4.16, 6.18), reward=-1.75), 3),
    "up": (Up(epoch=3, step=123, tips=TIPS, action=2), 3),
    "cmd": (Cmd(epoch=3, step=123, delta=-0.0174533), 4),
}


def verify(body: bytes, tag: bytes) -> bool:
    """What decode adds for the MAC: hash the body again and compare in constant time."""
    return hmac.compare_digest(codec.sign(body, KEY)[-codec.MAC_SIZE :], tag)


def median_us(fn: Any, number: int, repeats: int) -> float:
    return statistics.median(timeit.repeat(fn, number=number, repeat=repeats)) / number * 1e6


def measure(number: int, repeats: int) -> dict[str, dict[str, float]]:
    rows: dict[str, dict[str, float]] = {}
    for name, (msg, _) in SAMPLES.items():
        kind = type(msg)
        payload = codec.encode(msg, RUN, "a1", KEY)
        body, tag = payload[: -codec.MAC_SIZE], payload[-codec.MAC_SIZE :]
        rows[name] = {
            "bytes": float(len(payload)),
            "encode": median_us(lambda m=msg: codec.encode(m, RUN, "a1", KEY), number, repeats),
            "decode": median_us(lambda p=payload, k=kind: codec.decode(p, k, RUN, KEY), number, repeats),
            "both": median_us(
                lambda m=msg, k=kind: codec.decode(codec.encode(m, RUN, "a1", KEY), k, RUN, KEY), number, repeats
            ),
            "mac": median_us(lambda b=body, t=tag: (codec.sign(b, KEY), verify(b, t)), number, repeats),
        }
    rows["step"] = {
        col: sum(rows[name][col] * n for name, (_, n) in SAMPLES.items())
        for col in ("bytes", "encode", "decode", "both", "mac")
    }
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--number", type=int, default=20000)
    ap.add_argument("--json", type=Path)
    a = ap.parse_args()
    rows = measure(a.number, a.repeats)
    print(f"{'message':<8} {'bytes':>6} {'encode us':>10} {'decode us':>10} {'enc+dec us':>11} {'of it mac us':>13}")
    for name, r in rows.items():
        print(
            f"{name:<8} {r['bytes']:>6.0f} {r['encode']:>10.2f} {r['decode']:>10.2f} {r['both']:>11.2f}"
            f" {r['mac']:>13.2f}"
        )
    if a.json:
        a.json.write_text(json.dumps(rows, indent=2) + "\n")


if __name__ == "__main__":
    main()
