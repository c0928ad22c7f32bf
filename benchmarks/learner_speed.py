"""Cost of one agent's learner per step, decide() + observe(), against the numpy learner it replaced.

    python benchmarks/learner_speed.py [--epochs 3] [--steps 500] [--baseline REV] [--json out.json]

The paper's chain4 (4 joints, links of 3, start (0, 10, 20, 30) deg, goal (4.16, 6.18), 1 deg per action, shaped
reward) runs in this process as tests/test_learning_convergence.py runs it: each step the four learners step()
leaf first, each seeing its child's action. From epoch 0 with no phi row: the learning phase, with TD updates
creating rows. A fifth learner, seeing two agents, steps on a1's states with a2's and a3's actions (n_visible 2).

Baseline: the learner of commit REV (default: the last numpy one), its actors/learning taken from git and imported
as a package of its own (it imports only numpy and itself). Its learners get the same inputs in the same sitting,
call by call, the two taking turns to go first, and must choose the same actions: the compiled learner is bit for
bit the numpy one. The table gives medians in microseconds: per step() call for each n_visible (wall clock, each
call timed on its own), and per step for the chain's four learners together (this thread's CPU time, so that the
other work of a shared machine, which takes the CPU away for milliseconds at a time, does not count; timing the
four calls adds ~0.5 us). Shared machines are noisy: quote medians and ratios, with the load average printed.
"""

from __future__ import annotations

import argparse
import importlib
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from types import ModuleType
from typing import Any

from kinswarm.actors import learning
from kinswarm.actors.tasks.reach import reach_reward

ROOT = Path(__file__).resolve().parent.parent
NUMPY_LEARNER = "4f598d9"  # the last commit whose learner is numpy only
LINK, N, STEP, GOAL = 3.0, 4, math.radians(1.0), (4.16, 6.18)


def baseline_package(rev: str, into: Path) -> ModuleType:
    """actors/learning at commit rev, imported as the package `baseline_learning` from a copy in `into`."""
    pkg = into / "baseline_learning"
    pkg.mkdir()
    names = subprocess.run(
        ["git", "-C", str(ROOT), "ls-tree", "--name-only", f"{rev}:actors/learning"],
        check=True,
        capture_output=True,
        text=True,
    ).stdout.split()
    for name in names:
        if name.endswith(".py"):
            src = subprocess.run(
                ["git", "-C", str(ROOT), "show", f"{rev}:actors/learning/{name}"], check=True, capture_output=True
            ).stdout
            (pkg / name).write_bytes(src)
    sys.path.insert(0, str(into))
    return importlib.import_module("baseline_learning")


def chain(lib: ModuleType, q: list[float]) -> tuple[list, tuple[float, float]]:
    frames, base = [], (0.0, 0.0, 0.0)
    for qi in q:
        f = lib.joint_frame(base, (0.0, 0.0, 0.0), qi)
        frames.append(f)
        base = lib.link_end(f, LINK)
    return frames, base[:2]


def learners(lib: ModuleType, seed: int) -> list:
    """a1..a4 of the chain (a4 the leaf), and the fifth learner seeing two agents."""
    st = lib.LearnerSettings.for_reach(LINK * N)
    return [lib.Learner(st, int(i < N - 1), [seed, i]) for i in range(N)] + [lib.Learner(st, 2, [seed, N])]


def warm_up(lib: ModuleType) -> None:
    """Load (or compile) the compiled learner's code before anything is timed."""
    for ln in learners(lib, 99):
        ln.start_epoch(0)
        for t in range(3):
            s = lib.agent_state((0.0, 0.0, 0.1 * t), 0.1 * t, (5.0, 5.0), GOAL)
            ln.step(s, None if t == 0 else -1.0, [1] * ln.n_visible)


def run(epochs: int, steps: int, libs: dict[str, ModuleType], seed: int = 0) -> dict[str, Any]:
    """The chain's epochs with every library's learners on the same inputs; each step() call timed (ns)."""
    swarms = {name: learners(lib, seed) for name, lib in libs.items()}
    times: dict[str, list[list[int]]] = {name: [[] for _ in range(N + 1)] for name in libs}
    steps_cpu: dict[str, list[int]] = {name: [] for name in libs}
    same, order = True, list(libs)
    lib = learning
    for epoch in range(epochs):
        q = [math.radians(a) for a in (0, 10, 20, 30)]
        for swarm in swarms.values():
            for ln in swarm:
                ln.start_epoch(epoch)
        D_prev = None
        for _ in range(steps):
            frames, tip = chain(lib, q)
            D = math.dist(tip, GOAL)
            r = None if D_prev is None else reach_reward(D, D_prev, "shaped")
            D_prev = D
            states = [lib.agent_state(frames[i], q[i], tip, GOAL) for i in range(N)]
            order.reverse()  # the two take turns to go first
            acts: dict[str, list[int]] = {}
            for name in order:
                swarm, clock = swarms[name], times[name]
                a, child = [0] * (N + 1), None
                cpu = time.thread_time_ns()
                for i in range(N - 1, -1, -1):  # leaf first
                    vis = [] if child is None else [child]
                    t0 = time.perf_counter_ns()
                    a[i] = child = swarm[i].step(states[i], r, vis)
                    clock[i].append(time.perf_counter_ns() - t0)
                steps_cpu[name].append(time.thread_time_ns() - cpu)
                t0 = time.perf_counter_ns()
                a[N] = swarm[N].step(states[0], r, [a[1], a[2]])
                clock[N].append(time.perf_counter_ns() - t0)
                acts[name] = a
            same = same and len({tuple(a) for a in acts.values()}) == 1
            a = acts[order[0]]
            q = [min(max(qi + (ai - 1) * STEP, -math.pi), math.pi) for qi, ai in zip(q, a[:N], strict=True)]
    out: dict[str, Any] = {"identical_actions": same, "learners": {}}
    for name, clock in times.items():
        out["learners"][name] = {
            "n_visible_0_us": statistics.median(clock[N - 1]) / 1e3,
            "n_visible_1_us": statistics.median([x for c in clock[: N - 1] for x in c]) / 1e3,
            "n_visible_2_us": statistics.median(clock[N]) / 1e3,
            "chain4_step_us": statistics.median(steps_cpu[name]) / 1e3,
            "rows": [ln.rules_used for ln in swarms[name]],
        }
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--epochs", type=int, default=3)
    ap.add_argument("--steps", type=int, default=500)
    ap.add_argument("--baseline", default=NUMPY_LEARNER, help="commit of the numpy learner ('' for none)")
    ap.add_argument("--json", type=Path)
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        libs = {"compiled": learning}
        if a.baseline:
            libs = {"numpy": baseline_package(a.baseline, Path(tmp)), **libs}
        t0 = time.perf_counter()
        warm_up(learning)
        warm = time.perf_counter() - t0
        res = run(a.epochs, a.steps, libs)
    res.update(epochs=a.epochs, steps=a.steps, baseline=a.baseline, warm_up_s=warm, load=os.getloadavg())
    cols = ("n_visible_0_us", "n_visible_1_us", "n_visible_2_us", "chain4_step_us")
    print("medians in us: per step() call (decide + observe) and per chain4 step (the four learners' CPU time);")
    print(f"{a.epochs} epochs x {a.steps} steps of chain4 from an empty phi")
    print(f"{'':12}" + "".join(f"{c.removesuffix('_us'):>16}" for c in cols))
    for name, row in res["learners"].items():
        print(f"{name:12}" + "".join(f"{row[c]:16.1f}" for c in cols))
    if "numpy" in res["learners"]:
        old, new = res["learners"]["numpy"], res["learners"]["compiled"]
        print(f"{'ratio':12}" + "".join(f"{old[c] / new[c]:15.1f}x" for c in cols))
        print(f"identical actions: {res['identical_actions']}; rows {new['rows']} (numpy {old['rows']})")
    print(f"warm-up (compiled code loaded or compiled): {warm:.2f} s; load average {res['load'][0]:.2f}")
    if a.json:
        a.json.write_text(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
