"""Tuning reach3d in a plain loop (research): the iiwa's seven learners, their rotation-plane states and the root's
graded reward, stepped one after the other in one process — no wire, no simulator process, the arm's model
(protocol/frames.py) for its pose. The same Learner, state, reward and g_rot as the swarm; only the message passing
is gone, so a training takes about a minute, not several. It chose the settings of `kinswarm experiment reach3d`;
the report's numbers are the swarm's own, not these.

    python -m kinswarm.experiments.research reach3d_loop --out runs/research          # the variants below, ~20 min
    python -m kinswarm.experiments.research reach3d_loop --quick --out runs/research  # seconds

Measured (seed 0 unless said; within 5 cm of 100 unseen goals from random starts, test sets A / B of the reach3d
experiment, frozen after training; 2026-11-24, a loaded 2-core machine):
- points, 300 steps: 48 goals x 4 passes 89 %; 96 x 4 92 % (seed 1: 93 % / 86 %); 128 x 3 89 %; q out of the
  state 78 %; epsilon_decay 0.03 87 %. 400 steps, 96 x 4: 97 % / 92 % (seed 1: 96 % / 93 %); g_perp in 11 sets
  96 % / 90 % (seed 1: 92 % / 86 %). The rule on g_perp: 95 % (set A, 300 steps).
- poses (within 5 cm and 15°, set A): 96 x 4, 300 steps 35 % (mean 3.9 cm, 30.6°); the rule 30 % (6.1 cm, 31°).
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np
from kinswarm.actors.agent.geometry import Spatial
from kinswarm.actors.learning.learner import Learner
from kinswarm.actors.learning.settings import LearnerSettings
from kinswarm.actors.tasks.reach import reach_reward
from kinswarm.actors.tasks.reach3d import G_ROT, distance, wire_goal
from kinswarm.experiments import reach3d as r3
from kinswarm.experiments.common import Context
from kinswarm.protocol import frames
from kinswarm.protocol.topology import Topology, load_robot

SEEDS = 1
INC = math.radians(1)
# (label, learner overrides, goals, passes, steps, pose)
VARIANTS: tuple[tuple[str, dict[str, Any], int, int, int, bool], ...] = (
    ("points, 96 x 4, 300 steps", {}, 96, 4, 300, False),
    ("points, 96 x 4, 400 steps", {}, 96, 4, 400, False),
    ("points, 96 x 4, 400 steps, g_perp 11 sets", {"n_sets": (5, 5, 11, 5, 5, 6)}, 96, 4, 400, False),
    ("poses, 96 x 4, 400 steps", {}, 96, 4, 400, True),
)


class Loop:
    """One swarm's learners stepped in turn: each step every agent decides on its state, then observes its children."""

    def __init__(self, topo: Topology, seed: int, pose: bool, overrides: dict[str, Any]) -> None:
        self.topo, self.pose, self.geom = topo, pose, Spatial()
        self.learners: dict[str, tuple[Learner, list[str]]] = {}
        for i, a in enumerate(topo.dof_agents):
            st = LearnerSettings.for_plane(topo.reach, topo.reach_below(a), topo.agents[a].limits, **overrides)
            if pose:
                st = st.with_task_state((G_ROT,))
            children = list(topo.agents[a].children)
            self.learners[a] = (Learner(st, len(children), [seed, i]), children)

    def episode(self, goal: tuple[float, ...], start: list[float], epoch: int, steps: int, learn: bool) -> tuple:
        topo = self.topo
        q = {a: math.radians(v) for a, v in zip(topo.dof_agents, start, strict=True)}
        for learner, _ in self.learners.values():
            learner.start_epoch(epoch)
        D_prev = None
        for _ in range(steps):
            links = frames.link_frames(topo, q)
            (tip,) = frames.tips(topo, q).values()
            D = distance(tip, goal)
            r = None if D_prev is None else reach_reward(D, D_prev, "graded", D_min=0.3, c=10.0, k=200.0)
            D_prev = D
            turn = frames.orientation_error(tip[3:7], goal[3:7]) if self.pose else None
            acts = {}
            for a, (learner, _) in self.learners.items():
                spec = topo.agents[a]
                s = self.geom.state(spec, links[a], q[a], tip, goal, False)
                if turn is not None:
                    axis = frames.joint_axis(spec, links[a])
                    s = np.append(s, sum(x * y for x, y in zip(turn, axis, strict=True)))
                acts[a] = learner.decide(s, r, learn=learn, explore=learn)
            for learner, children in self.learners.values():
                learner.observe([acts[c] for c in children], learn=learn)
            for a, act in acts.items():
                lo, hi = topo.agents[a].limits
                q[a] = min(max(q[a] + (act - 1) * INC, lo), hi)
        (tip,) = frames.tips(topo, q).values()
        angle = math.degrees(frames.angle_between(tip[3:7], goal[3:7])) if self.pose else 0.0
        return math.dist(tip[:3], goal[:3]), angle


def run(ctx: Context) -> dict[str, Any]:
    topo = load_robot(r3.ROBOT)
    results: dict[str, Any] = {}
    for label, overrides, n_goals, passes, steps, pose in VARIANTS:
        if ctx.quick:
            n_goals, passes, steps = 3, 1, 30
        goals, starts = r3.training_set(topo, pose, n_goals, passes)
        for seed in ctx.seed_list:
            loop = Loop(topo, seed, pose, dict(overrides))
            for e, (g, s) in enumerate(zip(goals, starts, strict=True)):
                loop.episode(wire_goal(tuple(g)), s, e, steps, learn=True)
            row = {}
            for name, sample_seed in r3.SETS.items():
                test_goals, test_starts = r3.sample(
                    topo, sample_seed + (7 if pose else 0), 3 if ctx.quick else 100, pose
                )
                ends = [
                    loop.episode(wire_goal(tuple(g)), s, 0, steps, False)
                    for g, s in zip(test_goals, test_starts, strict=True)
                ]
                ok = [d <= r3.TOL and a <= r3.TOL_DEG for d, a in ends]
                row[name] = {"within_pct": 100.0 * float(np.mean(ok)), "mean_m": float(np.mean([d for d, _ in ends]))}
            results[f"{label} | seed {seed}"] = row
            print(label, seed, row, flush=True)
    ctx.out.mkdir(parents=True, exist_ok=True)
    (ctx.out / "results.json").write_text(json.dumps(results, indent=1) + "\n")
    return results
