"""Closed-form kinematics against hand-computed values and finite differences."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from kinswarm.protocol.robots import load_robot, parse_robot
from kinswarm.protocol.topology import Topology
from kinswarm.sim import kinematics

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def deg(*values: float) -> list[float]:
    return [math.radians(v) for v in values]


@pytest.fixture(scope="module")
def chain4() -> Topology:
    return load_robot(EXAMPLES / "chain4.toml")


@pytest.fixture(scope="module")
def tree5() -> Topology:
    return load_robot(EXAMPLES / "tree5.toml")


def compound_tree() -> Topology:
    """Non-zero base, offsets and a compound passthrough agent: exercises every term of the convention."""
    return parse_robot(
        {
            "name": "mixed",
            "base": [1.0, -2.0, 30.0],
            "agent": [
                {"id": "r", "link_length": 2.0, "initial_deg": 15.0, "offset": [0.5, 0.25, 10.0]},
                {"id": "hand", "parent": "r", "compound": True, "offset": [0.3, -0.1, -20.0]},
                {"id": "f1", "parent": "hand", "link_length": 1.0, "offset": [0.0, 0.4, 45.0]},
                {"id": "f2", "parent": "hand", "link_length": 1.5, "offset": [0.0, -0.4, -45.0]},
                {"id": "f2b", "parent": "f2", "link_length": 0.7, "initial_deg": -30.0},
            ],
        }
    )


def test_chain4_initial_tip_by_hand(chain4: Topology) -> None:
    # Absolute headings 0, 10, 30, 60 deg; links of 3.
    hs = deg(0, 10, 30, 60)
    want = (3 * sum(math.cos(h) for h in hs), 3 * sum(math.sin(h) for h in hs), hs[-1])
    (got,) = kinematics.tips(chain4, chain4.initial_angles()).values()
    assert got == pytest.approx(want, abs=1e-12)
    assert got[:2] == pytest.approx((10.052499470, 4.619020744), abs=1e-8)


def test_chain4_frames_and_link_ends(chain4: Topology) -> None:
    q = chain4.initial_angles()
    fr, ends = kinematics.frames(chain4, q), kinematics.link_ends(chain4, q)
    assert fr["a1"] == pytest.approx((0.0, 0.0, 0.0))
    assert fr["a2"] == pytest.approx((3.0, 0.0, math.radians(10)))
    assert ends["a1"] == pytest.approx(fr["a2"][:2] + (0.0,))
    for parent, child in (("a1", "a2"), ("a2", "a3"), ("a3", "a4")):
        assert ends[parent][:2] == pytest.approx(fr[child][:2])


def test_chain4_ls_optimal_reaches_default_goal(chain4: Topology) -> None:
    q = dict(zip(chain4.dof_agents, deg(0, 24.1, 53.7, 59.8), strict=True))
    (tip,) = kinematics.tips(chain4, q).values()
    assert tip[:2] == pytest.approx((4.16, 6.18), abs=5e-3)
    assert tip[2] == pytest.approx(math.radians(0 + 24.1 + 53.7 + 59.8))


def test_compound_offsets_base_by_hand() -> None:
    topo = compound_tree()
    fr = kinematics.frames(topo, topo.initial_angles())
    # Root joint: base (1, -2) plus R(30 deg) (0.5, 0.25); heading 30 + 10 + 15.
    c, s = math.cos(math.radians(30)), math.sin(math.radians(30))
    assert fr["r"] == pytest.approx((1 + c * 0.5 - s * 0.25, -2 + s * 0.5 + c * 0.25, math.radians(55)))
    # Compound: no DOF, zero-length link, so its children's base is its own joint frame.
    assert "hand" not in topo.dof_agents
    ends = kinematics.link_ends(topo, topo.initial_angles())
    assert ends["hand"] == pytest.approx(fr["hand"])
    assert fr["hand"][2] == pytest.approx(math.radians(55 - 20))
    assert set(kinematics.tips(topo, topo.initial_angles())) == {"f1", "f2b"}


@pytest.mark.parametrize("which", ["chain4", "tree5", "compound"])
def test_jacobian_matches_finite_differences(which: str, chain4: Topology, tree5: Topology) -> None:
    topo = {"chain4": chain4, "tree5": tree5, "compound": compound_tree()}[which]
    rng = np.random.default_rng(7)
    eps = 1e-6
    for _ in range(5):
        q = {a: float(rng.uniform(-math.pi, math.pi)) for a in topo.dof_agents}
        for leaf in topo.end_effectors:
            jac = kinematics.jacobian(topo, q, leaf)
            assert jac.shape == (2, len(topo.dof_agents))
            for col, a in enumerate(topo.dof_agents):
                hi = kinematics.tips(topo, {**q, a: q[a] + eps})[leaf]
                lo = kinematics.tips(topo, {**q, a: q[a] - eps})[leaf]
                fd = ((hi[0] - lo[0]) / (2 * eps), (hi[1] - lo[1]) / (2 * eps))
                assert jac[:, col] == pytest.approx(fd, abs=1e-6)


def test_jacobian_zero_off_path(tree5: Topology) -> None:
    jac = kinematics.jacobian(tree5, tree5.initial_angles(), "l2")
    cols = dict(zip(tree5.dof_agents, jac.T, strict=True))
    assert not cols["r1"].any() and not cols["r2"].any()
    assert cols["base"].any() and cols["l1"].any() and cols["l2"].any()
