"""What test_tip.py and test_tip3d.py compare of a run with `tip = "sensed"` (the planar reach's and reach3d's): an
inprocess run's every error, what each agent's aim moved the goal by at each step (the mechanism's decisions), and
every agent's Q-values and counts at the end."""

from __future__ import annotations

import numpy as np
from kinswarm.actors.run.inprocess import InProcessRun
from kinswarm.actors.tasks.base import StepView


def watched(run: InProcessRun, epochs: int) -> tuple[list, list]:
    """Runs `epochs` epochs of `run` and closes it: [errors, aims, learned], and the events the run recorded."""
    aims: list[tuple[float, ...]] = []
    for st in run.swarm.agents.values():  # what each agent's task makes of the goal, step by step
        own = st.task.aim

        def aim(view: StepView, own=own) -> tuple[float, ...]:
            a = own(view)
            aims.append(tuple(x - g for x, g in zip(a, view.goal, strict=True)))
            return a

        st.task.aim = aim  # type: ignore[method-assign]
    events: list = []
    errors: list = []
    try:
        for epoch in range(epochs):
            errors.append(run.epoch(epoch, lambda *e: events.append(e)).errors)
        learned = [(run.learners[a].q.phi.copy(), run.learners[a].counts.copy()) for a in sorted(run.learners)]
    finally:
        run.close()
    return [errors, aims, learned], events


def same(a: list, b: list) -> bool:
    """The same errors and aims to the bit, and the same Q-values and counts in every agent."""
    return (
        a[0] == b[0]
        and a[1] == b[1]
        and all(np.array_equal(p, q) and np.array_equal(c, d) for (p, c), (q, d) in zip(a[2], b[2], strict=True))
    )
