"""The corridor's body-aware local term ("follow the leader", the corridor task's follow_leader): each of the last
links' agents is rewarded for bringing its own link end towards its place on the corridor's axis."""

from __future__ import annotations

import math

import pytest
from conftest import EXAMPLES, run_config
from kinswarm.actors.files.runfile import task_of
from kinswarm.actors.tasks.corridor import _follow_leader_behind, follow_leader_distance
from kinswarm.actors.tasks.reach import path_distance
from kinswarm.protocol.spec import SpecError

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
    with pytest.raises(SpecError, match="task.follow_leader: must be >= 0"):
        run_config(GUIDED, ["task.follow_leader=-1.0"])
    with pytest.raises(SpecError, match="task.follow_leader_links: must be >= 1"):
        run_config(GUIDED, ["task.follow_leader_links=0"])

    def behind(sets: list[str], *agents: str) -> list[float | None]:
        task = task_of(run_config(GUIDED, sets))
        return [_follow_leader_behind(task.topo, a, task.settings) for a in agents]

    # the last 4 agents: a7 (the end effector, 0 behind) ... a4 (3 links behind); a1-a3 get no term
    on = ["task.follow_leader=20.0"]
    assert behind(on, "a7", "a6", "a5", "a4") == [0.0, 1.0, 2.0, 3.0]
    assert behind(on, "a3", "a2", "a1") == [None, None, None]
    assert behind([], "a7") == [None]
    assert behind(["task.follow_leader=1.0", "task.follow_leader_links=2"], "a7", "a6", "a5") == [0.0, 1.0, None]
    # without via there is no axis: a clear error naming the override
    with pytest.raises(SpecError, match=r"^--set task.follow_leader=1.0: task.follow_leader: needs via"):
        run_config(EXAMPLES / "corridor7.toml", ["task.follow_leader=1.0"])
