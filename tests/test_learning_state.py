"""Planar state of §3.3 on hand-computed geometry."""

import math

import numpy as np
import pytest
from kinswarm.actors.learning import agent_state, joint_frame, link_end
from kinswarm.actors.learning.state import goal_along_motion, own_extras


def test_joint_frame_and_link_end():
    f = joint_frame((1.0, 1.0, math.pi / 2), (2.0, 0.0, 0.1), 0.2)
    assert f == pytest.approx((1.0, 3.0, math.pi / 2 + 0.3))
    assert link_end((0.0, 0.0, math.pi / 2), 3.0) == pytest.approx((0.0, 3.0, math.pi / 2))
    assert link_end((1.0, 2.0, 0.0), 3.0) == pytest.approx((4.0, 2.0, 0.0))


def test_agent_state_hand_computed():
    # joint at (1, 0) heading 90 deg, tip straight ahead at (1, 2), goal at (0, 2)
    s = agent_state((1.0, 0.0, math.pi / 2), 0.7, (1.0, 2.0), (0.0, 2.0))
    q, theta, d, g1, g2, g3 = s
    assert q == 0.7 and d == pytest.approx(2.0) and theta == pytest.approx(0.0, abs=1e-12)
    # goal - tip = (-1, 0) in the world = (0, +1) in the frame heading 90 deg (to the agent's left)
    assert (g1, g2) == pytest.approx((0.0, 1.0), abs=1e-12)
    # joint->tip points along +y, tip->goal along -x: a left turn of 90 deg
    assert g3 == pytest.approx(math.pi / 2)


def test_agent_state_sideways_tip_and_degenerate():
    s = agent_state((0.0, 0.0, 0.0), 0.0, (0.0, -3.0), (0.0, -3.0))
    assert s[1] == pytest.approx(-math.pi / 2) and s[2] == pytest.approx(3.0)
    assert s[5] == 0.0 and s[3] == 0.0 and s[4] == 0.0  # tip on the goal: g3 degenerate -> 0
    assert isinstance(s, np.ndarray) and s.shape == (6,)


def test_g3_unsigned_is_the_size_of_the_bearing():
    # joint at the origin heading +x, tip at (2, 0); goals to the right of, left of and straight behind the tip
    for goal, signed in (((2.0, -1.0), -math.pi / 2), ((2.0, 1.0), math.pi / 2), ((1.0, 0.0), math.pi)):
        s = agent_state((0.0, 0.0, 0.0), 0.0, (2.0, 0.0), goal)
        u = agent_state((0.0, 0.0, 0.0), 0.0, (2.0, 0.0), goal, g3_unsigned=True)
        assert s[5] == pytest.approx(signed) and u[5] == pytest.approx(abs(signed))
        assert np.array_equal(s[:5], u[:5])  # only g3 changes
    # a goal just behind the tip, either side: far apart signed (+-pi), together unsigned
    left = agent_state((0.0, 0.0, 0.0), 0.0, (2.0, 0.0), (1.0, 1e-6), g3_unsigned=True)[5]
    right = agent_state((0.0, 0.0, 0.0), 0.0, (2.0, 0.0), (1.0, -1e-6), g3_unsigned=True)[5]
    assert left == pytest.approx(right) == pytest.approx(math.pi)


def test_g3_unsigned_needs_a_range_from_zero():
    from kinswarm.actors.learning.settings import LearnerSettings

    with pytest.raises(ValueError, match="g3 'unsigned' lies in"):
        LearnerSettings(g3="unsigned")  # default ranges: g3 over (-pi, pi)
    with pytest.raises(ValueError, match="g3 must be one of"):
        LearnerSettings(g3="both")
    r = LearnerSettings().ranges
    assert LearnerSettings(g3="unsigned", ranges=(*r[:5], (0.0, math.pi))).g3 == "unsigned"


def test_own_extras_computes_only_what_is_named():
    """g_perp is the only variable an agent computes from its own geometry; the others come from its task or
    readings."""
    frame, tip, goal = (0.0, 0.0, 0.0), (3.0, 0.0), (3.3, 0.4)
    assert own_extras(("force_error", "g_perp"), frame, tip, goal) == {
        "g_perp": pytest.approx(goal_along_motion(frame, tip, goal))
    }
    assert own_extras(("force_error",), frame, tip, goal) == {}  # a reading's, not the agent's
