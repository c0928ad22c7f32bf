"""Steps per second of the two env faces (kinswarm.env) with random actions, the actions drawn before the clock starts.

    python benchmarks/env_rate.py [--steps 2000] [--examples chain4 iiwa]

Each example: gym_env (MultiDiscrete) and parallel_env, 500-step episodes (the resets inside the timed loop, as a
training loop has them), this thread's CPU time, so that a shared machine's other work does not count. What it
costs: the step library's passes (actors/step/passes.py) over every agent, and the robot's PyBullet move.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

from kinswarm.env import gym_env, parallel_env

ROOT = Path(__file__).resolve().parents[1]


def rates(name: str, steps: int) -> tuple[float, float]:
    run_file = str(ROOT / "examples" / f"{name}.toml")
    env = gym_env(run_file, steps=500)
    try:
        env.reset(seed=0)
        env.action_space.seed(0)
        actions = [env.action_space.sample() for _ in range(steps)]
        t0 = time.thread_time()
        for a in actions:
            if env.step(a)[3]:
                env.reset()
        gym_rate = steps / (time.thread_time() - t0)
    finally:
        env.close()
    par = parallel_env(run_file, steps=500)
    try:
        par.reset(seed=0)
        joint = [{a: par.action_space(a).sample() for a in par.possible_agents} for _ in range(steps)]
        t0 = time.thread_time()
        for a in joint:
            if not par.agents:
                par.reset()
            par.step(a)
        par_rate = steps / (time.thread_time() - t0)
    finally:
        par.close()
    return gym_rate, par_rate


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--examples", nargs="+", default=["chain4", "iiwa"])
    args = ap.parse_args()
    print(f"load average {os.getloadavg()[0]:.2f}")
    print(f"{'example':<14}{'gym_env':>12}{'parallel_env':>14}   (steps/s, CPU time)")
    for name in args.examples:
        g, p = rates(name, args.steps)
        print(f"{name:<14}{g:>12.0f}{p:>14.0f}")


if __name__ == "__main__":
    main()
