"""The top-down/bottom-up state passes of the step library (actors/step/passes.py, what every placement computes),
against closed-form planar kinematics."""

import math

import numpy as np
import pytest
from conftest import run_config
from kinswarm.actors.files.runfile import learner_settings, task_of
from kinswarm.actors.step.passes import AgentPasses, robot_passes
from kinswarm.protocol.messages import Task
from kinswarm.sim import kinematics


def passes(cfg, angles, goal):
    """The library's passes over a robot at `angles` (robot_passes: down = base frames root -> leaves; up = tips leaves
    -> root), then each agent's state S_i (its first six variables)."""
    topo, task = cfg.topo(), task_of(cfg)
    obs = {a: s.observation for a, s in learner_settings(task, cfg.learner, cfg.source).items()}
    agents = {a: AgentPasses(topo, a, task, obs.get(a), cfg.action_rad) for a in topo.order}
    head = Task(epoch=0, step=0, goal=goal, tips=kinematics.tips(topo, angles), sense={})
    begun, views = robot_passes(agents, topo.order, head, angles, {}, 0, 0, {})
    tips = {a: views[a].tip for a in topo.order}  # the end effector below each agent, as the up pass brought it
    states = {a: agents[a].decide_from(begun[a], views[a]).state[:6] for a in topo.order}
    return {a: b.frame for a, b in begun.items()}, tips, states


@pytest.mark.parametrize("name", ["chain4", "tree5"])
def test_passes_match_closed_form(name, chain4, tree5):
    cfg = run_config({"chain4": chain4, "tree5": tree5}[name])
    topo = cfg.topo()
    rng = np.random.default_rng(7)
    for _ in range(100):
        angles = {a: rng.uniform(*topo.agents[a].limits) for a in topo.dof_agents}
        goal = tuple(rng.uniform(-topo.reach, topo.reach, 2))
        frames, tips, states = passes(cfg, angles, goal)
        ref_frames = kinematics.frames(topo, angles)
        ref_tips = kinematics.tips(topo, angles)
        for a in topo.order:
            np.testing.assert_allclose(frames[a], ref_frames[a], atol=1e-12)
        for a in topo.order:  # each agent's end effector: its leaf's tip, or the centroid of its subtree's
            leaves = topo.subtree_leaves(a)
            want = [np.mean([ref_tips[leaf][i] for leaf in leaves]) for i in range(2)]
            np.testing.assert_allclose(tips[a][:2], want, atol=1e-12)
        for a in topo.order:
            q, theta, d, g1, g2, g3 = states[a]
            jx, jy, h = ref_frames[a]
            leaves = topo.subtree_leaves(a)
            tx = np.mean([ref_tips[leaf][0] for leaf in leaves])
            ty = np.mean([ref_tips[leaf][1] for leaf in leaves])
            # d_i, theta_i: polar coordinates of the end effector in the agent's frame
            assert d == pytest.approx(math.hypot(tx - jx, ty - jy), abs=1e-9)
            assert jx + d * math.cos(h + theta) == pytest.approx(tx, abs=1e-9)
            assert jy + d * math.sin(h + theta) == pytest.approx(ty, abs=1e-9)
            # g: goal relative to the end effector, rotated into the agent's frame (same length)
            assert math.hypot(g1, g2) == pytest.approx(math.hypot(goal[0] - tx, goal[1] - ty), abs=1e-9)
            gx = math.cos(h) * g1 - math.sin(h) * g2
            gy = math.sin(h) * g1 + math.cos(h) * g2
            assert (gx, gy) == pytest.approx((goal[0] - tx, goal[1] - ty), abs=1e-9)
            assert -math.pi <= g3 <= math.pi
            assert q == angles.get(a, 0.0)
