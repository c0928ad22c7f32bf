"""The top-down/bottom-up state passes, as the agents compute them, against closed-form planar kinematics."""

import math

import numpy as np
import pytest
from kinswarm.actors.learning.state import agent_state, joint_frame, link_end
from kinswarm.protocol.topology import load_robot
from kinswarm.sim import kinematics


def passes(topo, angles, goal):
    """Replay what travels on the wire: down = base frames root -> leaves; up = tips leaves -> root."""
    frames, ends = {}, {}
    for a in topo.order:  # top-down
        spec = topo.agents[a]
        base = topo.base if spec.parent is None else ends[spec.parent]
        frames[a] = joint_frame(base, spec.offset, angles.get(a, 0.0))
        ends[a] = link_end(frames[a], spec.link_length)
    tips = {}
    for a in reversed(topo.order):  # bottom-up
        if topo.agents[a].is_leaf:
            tips[a] = {a: ends[a]}
        else:
            tips[a] = {k: v for c in topo.agents[a].children for k, v in tips[c].items()}
    states = {}
    for a in topo.order:
        pts = np.array([t[:2] for t in tips[a].values()])
        states[a] = agent_state(frames[a], angles.get(a, 0.0), pts.mean(axis=0), goal)
    return frames, tips, states


@pytest.mark.parametrize("name", ["chain4", "tree5"])
def test_passes_match_closed_form(name, chain4, tree5):
    topo = load_robot({"chain4": chain4, "tree5": tree5}[name])
    rng = np.random.default_rng(7)
    for _ in range(100):
        angles = {a: rng.uniform(*topo.agents[a].limits) for a in topo.dof_agents}
        goal = tuple(rng.uniform(-topo.reach, topo.reach, 2))
        frames, tips, states = passes(topo, angles, goal)
        ref_frames = kinematics.frames(topo, angles)
        ref_tips = kinematics.tips(topo, angles)
        for a in topo.order:
            np.testing.assert_allclose(frames[a], ref_frames[a], atol=1e-12)
        for leaf, tip in tips[topo.root].items():
            np.testing.assert_allclose(tip, ref_tips[leaf], atol=1e-12)
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
