"""Experiment-scale check (pytest -m slow): the paper's planar 4R chain learns to reach its goal (§5.1).

Same loop as the tuning harness: links of 3, start (0, 10, 20, 30) deg, 1 deg per action, agents stepped
leaf first each seeing its child's action, shaped reward, 500 steps x 60 epochs.

It keeps this loop of its own, not the swarm's driver (actors/step/swarm.py): here an agent counts its child's action
of the same step (`Learner.step`, leaf first) and is seeded [seed, i], where every placement's agent counts its
children's actions a step late (they come up with the next step's pass) and is seeded by `agent_seed`; the driver
cannot give these numbers.
"""

import math

import numpy as np
import pytest
from kinswarm.actors.learning import (
    Learner,
    LearnerSettings,
    agent_state,
    joint_frame,
    link_end,
)
from kinswarm.actors.tasks.reach import reach_reward

LINK, N, STEP = 3.0, 4, math.radians(1.0)


def _chain(q):
    frames, base = [], (0.0, 0.0, 0.0)
    for qi in q:
        f = joint_frame(base, (0.0, 0.0, 0.0), qi)
        frames.append(f)
        base = link_end(f, LINK)
    return frames, base[:2]


def _train(seed, goal=(4.16, 6.18), epochs=60, steps=500, reward="shaped"):
    agents = [Learner(LearnerSettings.for_reach(LINK * N), n_visible=int(i < N - 1), seed=[seed, i]) for i in range(N)]
    finals = []
    for e in range(epochs):
        q = [math.radians(a) for a in (0, 10, 20, 30)]
        for a in agents:
            a.start_epoch(e)
        D_prev = None
        for _ in range(steps):
            frames, tip = _chain(q)
            D = math.dist(tip, goal)
            r = None if D_prev is None else reach_reward(D, D_prev, reward)
            D_prev = D
            acts, child = [0] * N, None
            for i in range(N - 1, -1, -1):
                vis = [] if child is None else [child]
                acts[i] = child = agents[i].step(agent_state(frames[i], q[i], tip, goal), r, vis)
            q = [min(max(qi + (ai - 1) * STEP, -math.pi), math.pi) for qi, ai in zip(q, acts, strict=True)]
        finals.append(math.dist(_chain(q)[1], goal))
    return np.array(finals)


@pytest.mark.slow
def test_chain4_reaches_goal_shaped():
    last = _train(seed=0)[-20:]
    assert np.mean(last <= 0.5) >= 0.8
    assert np.median(last) <= 0.15
