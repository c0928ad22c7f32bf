"""Step rate of the 4-joint chain in both placements, next to the wire floor measured in the same sitting.

    python benchmarks/step_rate.py [--repeats 3] [--epochs 3] [--steps 500] [--json out.json]

Each repeat is a full `kinswarm run` (learning on, the real PyBullet world, real Zenoh sessions);
steps/s is taken from the simulator's per-epoch timing (startup excluded), first epoch dropped as
warm-up. The wire floor is benchmarks/wire_floor.py (a bare relay down and up a chain of processes):
the fastest any step can go here. Quote medians and ratios; these machines are noisy.
benchmarks/floors.py prints the same rows with the in-process floor and every ratio as one table.
"""

from __future__ import annotations

import argparse
import json
import re
import socket
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from kinswarm.actors.cli.commands import _resolve, build_parser
from kinswarm.actors.run.launch import run_swarm

ROOT = Path(__file__).resolve().parent.parent
FLOOR = Path(__file__).resolve().parent / "wire_floor.py"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def swarm_rate(placement: str, epochs: int, steps: int, seed: int, fleet: int = 1) -> float:
    """Steps/s of the chain (robot-steps/s: times `fleet`, the robots each step moves)."""
    with tempfile.TemporaryDirectory() as d:
        a = build_parser().parse_args(
            [
                "run",
                str(ROOT / "examples" / "chain4.toml"),
                "--placement",
                placement,
                "--epochs",
                str(epochs),
                "--steps",
                str(steps),
                "--seed",
                str(seed),
                "--out",
                d,
                "--listen",
                f"tcp/127.0.0.1:{free_port()}",
                "--set",
                f"run.fleet={fleet}",
                "--set",
                "run.record=false",  # motion.gif and the recording: minutes of drawing, timed by no row
            ]
        )
        cfg, topo = _resolve(a, "agents")
        run_swarm(cfg, topo)
        rows = [json.loads(line) for line in (Path(d) / "metrics.jsonl").read_text().splitlines()]
    rows = rows[1:] or rows  # the first epoch warms caches and JIT-free code paths
    return fleet * sum(r["steps"] for r in rows) / sum(r["seconds"] for r in rows)


def wire_floor(mode: str, passes: int = 2000, attempts: int = 3) -> float | None:
    """Steps/s of the wire floor on a chain of 4 processes (chain4's depth); None if every attempt failed."""
    for _ in range(attempts):  # the chain takes port..port+3: a free first port makes a clash unlikely, not impossible
        port = str(free_port())
        cmd = [sys.executable, str(FLOOR), "--n", "4", "--passes", str(passes), "--mode", mode, "--port", port]
        out = subprocess.run(cmd, capture_output=True, text=True, timeout=600).stdout
        if m := re.search(r"= ~(\d+) steps/s", out):
            return float(m.group(1))
    return None


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--epochs", type=int, default=3)
    ap.add_argument("--steps", type=int, default=500)
    ap.add_argument("--json", type=Path, default=None)
    a = ap.parse_args()
    rates: dict[str, list[float]] = {"process": [], "single": []}
    floors: dict[str, list[float]] = {"async": [], "block": []}
    for r in range(a.repeats):  # interleaved, so drift on a shared machine hits every row alike
        for placement in rates:
            rates[placement].append(swarm_rate(placement, a.epochs, a.steps, seed=r))
        for mode in floors:
            f = wire_floor(mode)
            if f is not None:
                floors[mode].append(f)
    med = {k: statistics.median(v) for k, v in rates.items()}
    fmed = {k: statistics.median(v) for k, v in floors.items() if v}
    print(f"4-joint chain, {a.repeats} repeats x {a.epochs} epochs x {a.steps} steps (median steps/s)")
    print(f"{'':28}{'median':>10}{'min':>10}{'max':>10}{'target':>10}")
    for name, target in (("process (1 actor/process)", 700), ("single (1 process)", 3000)):
        v = rates[name.split()[0]]
        print(f"{name:28}{statistics.median(v):10.0f}{min(v):10.0f}{max(v):10.0f}{target:10d}")
    for mode, v in floors.items():
        if v:
            print(f"{'wire floor (' + mode + ')':28}{statistics.median(v):10.0f}{min(v):10.0f}{max(v):10.0f}")
    for mode in ("async", "block"):
        if mode in fmed:
            print(
                f"process / wire floor ({mode}): {med['process'] / fmed[mode]:.2f}    "
                f"single / wire floor ({mode}): {med['single'] / fmed[mode]:.2f}"
            )
    if a.json:
        a.json.write_text(json.dumps({"rates": rates, "floors": floors, "median": med, "floor_median": fmed}, indent=2))


if __name__ == "__main__":
    main()
