"""The corridor's body-aware local term ("follow the leader", LearnerSettings.follow_leader): each of the last
links' agents is rewarded for bringing its own link end towards its place on the corridor's axis."""

from __future__ import annotations

import math

import pytest
from conftest import EXAMPLES
from kinswarm.actors.agent import _follow_leader_behind, learner_settings
from kinswarm.actors.config import RunConfig
from kinswarm.actors.learning.learner import Learner
from kinswarm.actors.learning.reward import follow_leader_distance, path_distance
from kinswarm.actors.learning.settings import LearnerSettings
from kinswarm.protocol.topology import load_topology

GUIDED = EXAMPLES / "corridor7-guided.toml"
GOAL, VIA = (5.5, 2.0), (2.0, 2.0)


def test_follow_leader_distance_by_hand():
    # the end effector (nothing behind it) aims at the goal itself: the tip's path distance
    for p in [(4.0, 2.1), (1.0, 2.0), (5.5, 2.8)]:
        assert follow_leader_distance(p, GOAL, VIA, 0.0, 0.3) == pytest.approx(path_distance(p, GOAL, VIA, 0.3))
    # two links behind: the place (3.5, 2); in the band past via: straight; outside it: through via
    assert follow_leader_distance((3.0, 2.2), GOAL, VIA, 2.0, 0.3) == pytest.approx(math.hypot(0.5, 0.2))
    assert follow_leader_distance((3.0, 2.5), GOAL, VIA, 2.0, 0.3) == pytest.approx(math.hypot(1.0, 0.5) + 1.5)
    # the place behind via (4.5 back: (1, 2)): straight to it
    assert follow_leader_distance((0.0, 0.0), GOAL, VIA, 4.5, 0.3) == pytest.approx(math.hypot(1.0, 2.0))
    # zero at the place, and the straight-in configuration is zero for every link at once
    for k in range(4):
        assert follow_leader_distance((5.5 - k, 2.0), GOAL, VIA, float(k), 0.3) == pytest.approx(0.0)


def test_follow_leader_settings_and_agents():
    with pytest.raises(ValueError, match="follow_leader must be >= 0"):
        LearnerSettings(follow_leader=-1.0)
    with pytest.raises(ValueError, match="follow_leader_links must be an int >= 1"):
        LearnerSettings(follow_leader_links=0)
    topo = load_topology(GUIDED)
    on = Learner(LearnerSettings(follow_leader=20.0), 1, seed=0)
    # the last 4 agents: a7 (the end effector, 0 behind) ... a4 (3 links behind); a1-a3 get no term
    assert [_follow_leader_behind(topo, a, on) for a in ("a7", "a6", "a5", "a4")] == [0.0, 1.0, 2.0, 3.0]
    assert [_follow_leader_behind(topo, a, on) for a in ("a3", "a2", "a1")] == [None, None, None]
    off = Learner(LearnerSettings(), 1, seed=0)
    assert _follow_leader_behind(topo, "a7", off) is None
    two = Learner(LearnerSettings(follow_leader=1.0, follow_leader_links=2), 1, seed=0)
    assert [_follow_leader_behind(topo, a, two) for a in ("a7", "a6", "a5")] == [0.0, 1.0, None]
    # without [task] via there is no axis: a clear error naming the file
    cfg = RunConfig(run_id="r", topology=str(EXAMPLES / "corridor7.toml"), out="/tmp/x", learner={"follow_leader": 1.0})
    with pytest.raises(ValueError, match=r"follow_leader needs the scene's \[task\] via.*corridor7.toml"):
        learner_settings(cfg, cfg.topo())
