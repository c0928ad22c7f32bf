"""The 4-joint chain's step rate next to its floors, all measured in one sitting, as one table.

    python benchmarks/floors.py [--repeats 3] [--epochs 3] [--steps 500] [--passes 2000] [--fleets 1,8,64]
                                [--fleet-steps 100] [--rows process,wire] [--json out.json]

Rows (medians over the repeats, each repeat runs every row once, interleaved, so drift on a shared machine
hits every row alike):
  process        `kinswarm run examples/chain4.toml --placement process`: one OS process per agent plus the
                 simulator, real Zenoh sessions, learning on, the real PyBullet world (step_rate.swarm_rate)
  single         the same run with every actor in one process sharing one session
  wire (async)   benchmarks/wire_floor.py --mode async: a bare msgpack relay down and up a chain of 4 processes
                 over Zenoh, asyncio bridge; steps/s = one pass per 2*depth + 2 hops, as a swarm step needs
  wire (block)   the same with a blocking FifoChannel receive: the fastest any step can cross the wire here
  pattern        benchmarks/pattern_floor.py: the step's own 15 messages between 5 processes (obs and task out,
                 downs, ups, four cmds back) with bare relays, blocking receives: the fastest handlers doing
                 nothing can run this step's pattern here
  inprocess      the same run with `--placement inprocess`: the step library in a plain loop, the real PyBullet
                 world, no messages, no processes
  in-process     the floor: the same loop on the planar robot in closed form (sim/kinematics.ModelWorld), nothing
                 recorded — what the step costs in computation alone
  fleets         the same run with `run.fleet = B` (B robots through one swarm, actors/simulator/fleet.py), both
                 placements, --fleet-steps steps an epoch: robot-steps/s, and each over B = 1's in the same placement
  process (baseline)  with `--baseline PYTHON`: the process row run by another checkout's interpreter (its venv's
                 python, whose kinswarm is that checkout's), in the same repeats: a change's before and after
`--rows` keeps the rows whose names start with one of the given words (`process,wire`: the process placement
and both wire floors, alternated). Each repeat prints the load average (1 min) it started at: on a shared machine
the ratios of alternated rows stay fair, the rates do not. Ratios are each rate over a floor's median. Steps/s of a
swarm come from the simulator's per-epoch timing with the first epoch dropped (warm-up); the in-process loop is timed
the same way.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from kinswarm.actors.files.runfile import load_run
from kinswarm.actors.run.inprocess import InProcessRun
from kinswarm.sim import kinematics

# benchmarks/ is this script's directory, so first on sys.path
from step_rate import ROOT, free_port, swarm_rate, wire_floor

CHAIN4 = ROOT / "examples" / "chain4.toml"


def floor_rate(epochs: int, steps: int, seed: int) -> float:
    """The run's step as the step library computes it (actors/step/passes.py: the passes, the task's hooks, each
    agent's state, reward and choice; the learners' decide and observe), in the inprocess placement's plain loop, on the
    planar robot in closed form (sim/kinematics.ModelWorld) instead of PyBullet, nothing recorded: what the step costs
    in computation alone."""
    with tempfile.TemporaryDirectory() as d:
        cfg = load_run(CHAIN4, [f"run.seed={seed}", f"run.steps={steps}"], out=d)
        topo = cfg.topo()
        run = InProcessRun(cfg, topo, world=kinematics.ModelWorld(topo))
        seconds, done = 0.0, 0
        try:
            for epoch in range(epochs):
                t0 = time.perf_counter()
                run.epoch(epoch, lambda *event: None)
                if epoch > 0 or epochs == 1:  # the first epoch warms caches, as in the swarm's rate
                    seconds += time.perf_counter() - t0
                    done += steps
        finally:
            run.close()
    return done / seconds


def pattern_rate(passes: int, attempts: int = 3) -> float | None:
    """Steps/s of benchmarks/pattern_floor.py (the step's message pattern, bare relays); None if every attempt
    failed (it takes 5 consecutive ports from a free one: a clash is unlikely, not impossible)."""
    for _ in range(attempts):
        cmd = [sys.executable, str(Path(__file__).with_name("pattern_floor.py")), "--passes", str(passes)]
        out = subprocess.run([*cmd, "--port", str(free_port())], capture_output=True, text=True, timeout=600).stdout
        if out.strip().endswith("steps/s"):
            return float(out.split()[-2])
    return None


def baseline_rate(python: str, epochs: int, steps: int, seed: int) -> float:
    """step_rate.swarm_rate("process", ...) run by `python` (another checkout's venv): that checkout's swarm."""
    code = (
        f"import sys; sys.path.insert(0, {str(Path(__file__).resolve().parent)!r}); from step_rate import swarm_rate;"
        f" print(swarm_rate('process', {epochs}, {steps}, seed={seed}))"
    )
    out = subprocess.run([python, "-c", code], capture_output=True, text=True, timeout=900)
    if out.returncode != 0:
        raise SystemExit(f"--baseline {python}: the process row failed:\n{out.stderr[-2000:]}")
    return float(out.stdout.split()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--epochs", type=int, default=3)
    ap.add_argument("--steps", type=int, default=500)
    ap.add_argument("--passes", type=int, default=2000, help="round trips per wire floor measurement")
    ap.add_argument("--fleets", default="1,8,64", help="fleet sizes B to time in both placements ('' : none)")
    ap.add_argument("--fleet-steps", type=int, default=100, help="steps an epoch of the fleet runs")
    ap.add_argument("--rows", default="", help="keep only rows starting with one of these comma-separated words")
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--baseline", default="", help="another checkout's python: its process row beside this one's")
    a = ap.parse_args()
    fleets = [int(b) for b in a.fleets.split(",") if b.strip()]
    names = ["process", "single", "inprocess", "wire (async)", "wire (block)", "pattern", "in-process"]
    names += [f"{p} B={b}" for b in fleets for p in ("process", "single")]
    if a.baseline:
        names.insert(1, "process (baseline)")
    if a.rows:
        names = [n for n in names if n.startswith(tuple(w.strip() for w in a.rows.split(",") if w.strip()))]
    rows: dict[str, list[float]] = {name: [] for name in names}
    loads: list[float] = []
    for r in range(a.repeats):
        loads.append(os.getloadavg()[0])
        print(f"  repeat {r + 1}/{a.repeats}: load average {loads[-1]:.1f}", file=sys.stderr, flush=True)
        for name in rows:
            if " B=" in name:
                placement, b = name.split(" B=")
                v = swarm_rate(placement, a.epochs, a.fleet_steps, seed=r, fleet=int(b))
            elif name == "process (baseline)":
                v = baseline_rate(a.baseline, a.epochs, a.steps, seed=r)
            elif name in ("process", "single", "inprocess"):
                v = swarm_rate(name, a.epochs, a.steps, seed=r)
            elif name.startswith("wire"):
                v = wire_floor(name[6:-1], a.passes)
                if v is None:
                    raise SystemExit(f"benchmarks/wire_floor.py --mode {name[6:-1]} failed")
            elif name == "pattern":
                v = pattern_rate(a.passes)
                if v is None:
                    raise SystemExit("benchmarks/pattern_floor.py failed")
            else:
                v = floor_rate(a.epochs, a.steps, seed=r)
            rows[name].append(v)
            print(f"  repeat {r + 1}/{a.repeats}: {name:13} {v:8.0f} steps/s", file=sys.stderr, flush=True)
    med = {k: statistics.median(v) for k, v in rows.items()}
    floors = tuple(f for f in ("wire (block)", "wire (async)", "pattern", "in-process") if f in med)
    print(f"4-joint chain (examples/chain4.toml), {a.repeats} repeats, swarms {a.epochs} epochs x {a.steps} steps")
    print(f"load average (1 min) at each repeat's start: {', '.join(f'{x:.1f}' for x in loads)}")
    head = f"{'':14}{'median':>9}{'min':>9}{'max':>9}" + "".join(f"{'/ ' + f:>16}" for f in floors)
    print(head)
    for name, v in rows.items():
        if " B=" in name:
            continue
        ratios = "".join(f"{med[name] / med[f]:16.2f}" for f in floors)
        print(f"{name:14}{med[name]:9.0f}{min(v):9.0f}{max(v):9.0f}{ratios}")
    print("steps/s; ratios of medians. Targets: process >= 0.5 x wire (block) and >= 0.9 x wire (async).")
    fleets = [b for b in fleets if all(f"{p} B={b}" in med for p in ("process", "single"))]
    if fleets:
        print(f"\nfleets: {a.epochs} epochs x {a.fleet_steps} steps, robot-steps/s (median), / the placement's B=1")
        print(f"{'B':>6}" + "".join(f"{p:>12}{'/ B=1':>8}" for p in ("process", "single")))
        for b in fleets:
            cells = []
            for p in ("process", "single"):
                one = med.get(f"{p} B=1")
                cells.append(f"{med[f'{p} B={b}']:12.0f}" + (f"{med[f'{p} B={b}'] / one:8.2f}" if one else f"{'':8}"))
            print(f"{b:6}" + "".join(cells))
        print("Target: B=64 >= 20 x B=1 in both placements.")
    if a.json:
        a.json.write_text(json.dumps({"rows": rows, "median": med, "args": vars(a) | {"json": str(a.json)}}, indent=2))


if __name__ == "__main__":
    main()
