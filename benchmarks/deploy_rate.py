"""Step rate of the 4-joint chain split over two hosts (network namespaces on a bridge: the sim and the
root on one, a2-a4 on the other) against the same run on one host (`process` placement, loopback).

    sudo python benchmarks/deploy_rate.py [--repeats 1] [--epochs 4] [--steps 500]

Both are full runs (learning on, the real PyBullet world, real Zenoh sessions); steps/s comes from the
sim's per-epoch timing with the first epoch dropped as warm-up. Needs root (network namespaces).
Prints a table and the ratio; quote medians, these machines are noisy.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "benchmarks"))
from netns import Hosts  # noqa: E402
from step_rate import swarm_rate  # noqa: E402

KINSWARM = [sys.executable, "-m", "kinswarm.actors.cli"]


def rate(metrics: Path) -> float:
    rows = [json.loads(line) for line in metrics.read_text().splitlines()]
    rows = rows[1:] or rows
    return sum(r["steps"] for r in rows) / sum(r["seconds"] for r in rows)


def start_split(
    h: Hosts, tmp: Path, epochs: int, steps: int, seed: int, leader_args: Sequence[str] = ()
) -> subprocess.Popen:
    """`kinswarm up` on both hosts (the sim and a1 on brain, a2-a4 on limbs), run dirs under `tmp`; returns
    the leader's process (log: tmp/b.log). `leader_args`: more of the leader's flags (--run-id, --deadline-ms)."""
    plan = tmp / "plan.toml"
    plan.write_text(
        f'[plan]\nname = "bench"\nleader = "brain"\n[run]\nfile = "{ROOT / "examples" / "chain4.toml"}"\n'
        f'set = ["run.epochs={epochs}", "run.steps={steps}", "run.seed={seed}"]\n'
        f'[[host]]\nname = "brain"\naddress = "{h.address("brain")}"\nactors = ["sim", "a1"]\n'
        f'[[host]]\nname = "limbs"\naddress = "{h.address("limbs")}"\nactors = ["agents"]\n'
    )
    h.spawn("limbs", [*KINSWARM, "up", str(plan), "--host", "limbs", "--out", str(tmp / "limbs")], tmp / "l.log")
    return h.spawn(
        "brain", [*KINSWARM, "up", str(plan), "--host", "brain", "--out", str(tmp / "brain"), "--no-progress",
         *leader_args],
        tmp / "b.log",
    )  # fmt: skip


def two_hosts_rate(epochs: int, steps: int, seed: int) -> float:
    with tempfile.TemporaryDirectory() as d, Hosts(["brain", "limbs"]) as h:
        tmp = Path(d)
        leader = start_split(h, tmp, epochs, steps, seed)
        try:
            code = leader.wait(timeout=60 + epochs * steps / 20)
        except subprocess.TimeoutExpired:
            raise SystemExit(f"the two-host run did not end; its log:\n{(tmp / 'b.log').read_text()[-2000:]}") from None
        if code != 0:
            raise SystemExit(f"the two-host run failed ({code}):\n{(tmp / 'b.log').read_text()[-2000:]}")
        return rate(tmp / "brain" / "metrics.jsonl")


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--repeats", type=int, default=1)
    p.add_argument("--epochs", type=int, default=4)
    p.add_argument("--steps", type=int, default=500)
    a = p.parse_args()
    one, two = [], []
    for r in range(a.repeats):
        one.append(swarm_rate("process", a.epochs, a.steps, seed=r))
        two.append(two_hosts_rate(a.epochs, a.steps, seed=r))
    m1, m2 = statistics.median(one), statistics.median(two)
    print(f"| placement ({a.repeats} run(s), {a.epochs}x{a.steps} steps) | steps/s (median) | runs |")
    print("|---|---|---|")
    print(f"| one host, process placement (loopback) | {m1:.0f} | {', '.join(f'{v:.0f}' for v in one)} |")
    print(f"| two hosts (namespaces + bridge) | {m2:.0f} | {', '.join(f'{v:.0f}' for v in two)} |")
    print(f"\nratio two hosts / one host: {m2 / m1:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
