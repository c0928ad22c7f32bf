"""What the recording costs the step: the 4-joint chain with and without `--view FILE.rrd` (each epoch streamed
into a rerun recording by a process of its own, and every agent's trace sent once an epoch), interleaved.

    python benchmarks/recording_cost.py [--placement process|single] [--repeats 5] [--epochs 4] [--steps 500]

steps/s from the simulator's per-epoch timing (startup excluded, first epoch dropped as warm-up). Every run
also writes poses.jsonl (the pose after every step), with or without the viewer: the "without" column has that
cost in it. Quote the median ratio; these machines are noisy.
"""

from __future__ import annotations

import argparse
import json
import socket
import statistics
import tempfile
from pathlib import Path

from kinswarm.actors.cli.commands import _resolve, build_parser
from kinswarm.actors.run.launch import run_swarm

ROOT = Path(__file__).resolve().parent.parent


def port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def rate(view: bool, placement: str, epochs: int, steps: int, seed: int) -> float:
    with tempfile.TemporaryDirectory() as d:
        argv = ["run", str(ROOT / "examples" / "chain4.toml"), "--placement", placement, "--epochs", str(epochs)]
        argv += ["--steps", str(steps), "--seed", str(seed), "--out", f"{d}/run", "--listen", f"tcp/127.0.0.1:{port()}"]
        argv += ["--set", "run.record=false"]  # the end-of-run files are not the step's cost
        if view:
            argv += ["--view", f"{d}/live.rrd"]
        a = build_parser().parse_args(argv)
        cfg, topo = _resolve(a, "agents")
        run_swarm(cfg, topo, view=a.view)
        rows = [json.loads(line) for line in (Path(d) / "run" / "metrics.jsonl").read_text().splitlines()][1:]
    return sum(r["steps"] for r in rows) / sum(r["seconds"] for r in rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--placement", choices=("process", "single"), default="process")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--epochs", type=int, default=4)
    ap.add_argument("--steps", type=int, default=500)
    a = ap.parse_args()
    runs: dict[str, list[float]] = {"without": [], "with --view FILE.rrd": []}
    for r in range(a.repeats):
        runs["without"].append(rate(False, a.placement, a.epochs, a.steps, r))
        runs["with --view FILE.rrd"].append(rate(True, a.placement, a.epochs, a.steps, r))
    print(f"4-joint chain, {a.placement} placement, {a.repeats} repeats x {a.epochs} epochs x {a.steps} steps")
    print(f"{'':24}{'median steps/s':>16}{'min':>10}{'max':>10}")
    for name, v in runs.items():
        print(f"{name:24}{statistics.median(v):16.0f}{min(v):10.0f}{max(v):10.0f}")
    ratios = [w / o for w, o in zip(runs["with --view FILE.rrd"], runs["without"], strict=True)]
    print(f"with / without, median of paired ratios: {statistics.median(ratios):.3f}")


if __name__ == "__main__":
    main()
