"""Eq. 10 and its variants."""

import math

import pytest
from kinswarm.actors.tasks.reach import reach_reward


@pytest.mark.parametrize("mode", ["paper", "strict", "shaped", "settle"])
def test_inside_branches(mode):
    assert reach_reward(1.0, 1.5, mode) == pytest.approx(math.exp(-1.0))  # inside, approaching
    assert reach_reward(2.0, 1.5, mode, c=2.0) == -1.0  # inside, moving away
    assert reach_reward(3.0, 2.9, mode) == -1.0  # D == D_min moving away: our choice, -1
    assert reach_reward(3.0, 3.2, mode) == pytest.approx(math.exp(-3.0))  # D == D_min approaching


def test_paper_outside_and_still():
    assert reach_reward(5.0, 4.0, "paper") == -2.0
    assert reach_reward(5.0, 6.0, "paper") == -2.0
    assert reach_reward(1.0, 1.0, "paper") == pytest.approx(math.exp(-1.0))  # Delta D = 0 rewarded


def test_strict_still_inside_is_zero():
    assert reach_reward(1.0, 1.0, "strict") == 0.0
    assert reach_reward(1.0, 1.0 + 1e-13, "strict") == 0.0
    assert reach_reward(5.0, 5.0, "strict") == -2.0
    assert reach_reward(5.0, 4.0, "strict") == -2.0


def test_shaped_outside_gradient():
    assert reach_reward(5.0, 5.5, "shaped", k=20.0) == pytest.approx(-2.0 + 20 * 0.5)
    assert reach_reward(5.0, 4.9, "shaped", k=20.0) == pytest.approx(-2.0 - 2.0)
    assert reach_reward(1.0, 1.0, "shaped") == 0.0  # strict inside


def test_graded_has_the_gradient_inside_too():
    # outside D_min: as shaped
    assert reach_reward(5.0, 5.5, "graded", k=20.0) == reach_reward(5.0, 5.5, "shaped", k=20.0)
    # inside: strict plus k (D_prev - D), so a step towards the goal beats keeping still by more than e^(-c D)
    assert reach_reward(2.0, 2.1, "graded", k=20.0) == pytest.approx(math.exp(-2.0) + 20 * 0.1)
    assert reach_reward(2.1, 2.0, "graded", k=20.0) == pytest.approx(-1.0 - 20 * 0.1)
    assert reach_reward(2.0, 2.0, "graded") == 0.0  # keep: strict's 0, no gradient
    assert reach_reward(2.0, 2.1, "graded", k=0.0) == reach_reward(2.0, 2.1, "strict")


def test_settle_pays_an_arrived_tip_whatever_it_does():
    for D_prev in (0.1, 0.2, 0.3):  # within 0.3 at t - 1 and t: the approach reward, for keep and a step out too
        assert reach_reward(0.2, D_prev, "settle", c=0.5) == pytest.approx(math.exp(-0.1))
    assert reach_reward(0.2, 0.2, "shaped", c=0.5) == 0.0 and reach_reward(0.25, 0.2, "shaped") == -1.0
    # arriving and leaving are as in shaped; so is everything farther out
    for D, D_prev in ((0.3, 0.31), (0.31, 0.3), (1.0, 1.0), (2.0, 1.9), (5.0, 5.5), (5.0, 4.9)):
        assert reach_reward(D, D_prev, "settle") == reach_reward(D, D_prev, "shaped")


def test_unknown_mode():
    with pytest.raises(ValueError, match="allowed modes: shaped, paper, strict, graded, settle"):
        reach_reward(1.0, 1.0, "bogus")
