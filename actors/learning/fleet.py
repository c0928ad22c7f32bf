"""A fleet's agent (run.fleet = B > 1): one learner learning from the B robots' transitions.

The learner is one: one Q (its phi, Eq. 2), one set of fictitious-play counts (Eq. 7), one random generator, one
epoch's schedules. What is each robot's own is the transition it is in: the rules s(t-1) fired and their weights,
its pending joint action, its own action, and the step t of the temperature schedule (Eq. 8). A robot's lane swaps
its own into the learner for the length of each call, so lane b's calls compute exactly what one learner's calls
would, on the Q and counts the calls before it left (one thing is refreshed: a rule of s(t-1) that had no row of
phi when lane b decided may have been given one by another robot's update since); the agent makes them in a fixed
order (robot 0 first), so a fleet's run is as deterministic as one robot's. Every learner kind (kinds.py) is a
Learner keeping its transition in these fields, so each kind's lanes are these.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .learner import Learner

#: the Learner's attributes that are one transition's: each lane keeps its own
EPISODE = ("_fired", "_w", "_rules_and_O", "_latest", "_pending", "_own", "t")
#: of those, the ones a call rebinds (the arrays it fills in place: they are the lane's own already)
REBOUND = ("_latest", "_pending", "_own", "t")


class LearnerLane:
    """Robot b's view of a fleet agent's learner: decide, observe, start_epoch and resync on its own transition;
    anything else (settings, E, P just after its decide, checkpoints) is the learner's."""

    def __init__(self, learner: Learner) -> None:
        if not isinstance(learner, Learner):  # another learner's transition lives elsewhere: it needs its own lane
            raise TypeError(f"a fleet's lanes share a Learner, not a {type(learner).__name__}")
        self.learner = learner
        self.settings, self.n_actions, self.n_visible = learner.settings, learner.n_actions, learner.n_visible
        fired = np.zeros_like(learner._fired)
        fired[:, 1] = -1  # as a new learner's: no rule of s(t-1) updated yet
        w = np.zeros_like(learner._w)
        self._own_state: dict[str, Any] = {
            "_fired": fired,
            "_w": w,
            "_rules_and_O": [(fired[i, 0], w[i]) for i in (0, 1)],
            "_latest": 0,
            "_pending": None,
            "_own": 0,
            "t": 0,
        }

    def _call(self, method: str, *args: Any, **kwargs: Any) -> Any:
        learner, mine = self.learner, self._own_state
        if method == "decide":  # s(t-1)'s rules that had no phi row when this robot decided may have one now
            rules, rows = mine["_fired"][mine["_latest"]]
            if (rows < 0).any():  # another robot's update made it: the TD update (Eq. 6) must find that row
                rows[:] = learner.q.lookup(rules)  # rows never move: only the -1 entries change
        state = learner.__dict__
        state.update(mine)  # one call, not a setattr per name: a fleet makes this swap B times per call of a step
        try:
            return getattr(learner, method)(*args, **kwargs)
        finally:
            for name in REBOUND:
                mine[name] = state[name]

    # the calls of Learner that act on a transition, on this robot's (their arguments and results are Learner's)
    def decide(self, *args: Any, **kwargs: Any) -> int:
        return self._call("decide", *args, **kwargs)

    def observe(self, *args: Any, **kwargs: Any) -> None:
        self._call("observe", *args, **kwargs)

    def start_epoch(self, *args: Any, **kwargs: Any) -> None:
        self._call("start_epoch", *args, **kwargs)

    def resync(self, *args: Any, **kwargs: Any) -> None:
        self._call("resync", *args, **kwargs)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.learner, name)
