"""One agent's share of a step, as plain functions of what it holds: no messages in flight, no Zenoh, no asyncio.

The agent actor (actors/agent/actor.py) calls these as its messages arrive; the plain loops (the inprocess placement,
the env faces, the benchmarks' in-process floor, the research loops) call them through the driver (swarm.py). So the
step is written once:

  begin     the top-down pass: the head of the step (the task observation at the root, which its task turns into the
            goal and the reward r(t-1); a parent's `Down` elsewhere) and the joint's reading give the joint frame, the
            link's end (the children's base), and what each child is sent (goal, r(t-1), the task's context)
  finish    the bottom-up pass: the subtree's tips (a leaf's own, else its children's), the end effector below the agent
            (their centroid), and the `StepView` its task sees; `up` is what the parent gets
  decide    what the learner decides from (a `Decision`): S_i = <q_i, theta_i, d_i, g_i> (geometry.py) plus the task's
            and the learner's extra variables, the reward with the task's local terms, the moves to leave out, the
            action scale
  delta     the chosen action (0, 1, 2: decrease, keep, increase) as the joint's increment
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from kinswarm.actors.learning.observation import Observation
from kinswarm.actors.tasks.base import AgentTask, StepView, TaskDef
from kinswarm.protocol.messages import Down, Readings, Task, Up
from kinswarm.protocol.topology import Topology

from .geometry import geometry_of

Coords = tuple[float, ...]
KEEP = 1  # the action that holds the joint: actions 0, 1, 2 are decrease, keep, increase


@dataclass(slots=True)
class TopDown:
    """What the top-down pass gave an agent at a step: its frame, its link's end, its reading, the goal, r(t-1), the
    context from above and its own readings (`sense`), and what differs for each child (the root's task decides)."""

    frame: Coords
    end: Coords
    q: float
    goal: Coords
    reward: float | None
    context: Readings  # what its children inherit unless `children` says otherwise
    children: Mapping[str, tuple[Coords, float | None, Readings]]
    sense: Readings


@dataclass(slots=True)
class Decision:
    """What an agent with a joint decides from at a step, as its learner gets it."""

    state: np.ndarray  # S_i, as built (not clipped)
    reward: float | None  # r(t-1) with the task's local terms; None at an epoch's first step
    avoid: list[int]  # the moves its task leaves out of this step's choice
    scale: float  # the factor on its action size


class AgentPasses:
    """One agent's passes of a step over its constants (its place in the robot, its task, its learner's
    observation)."""

    def __init__(
        self, topo: Topology, agent_id: str, task: TaskDef, obs: Observation | None, action_rad: float
    ) -> None:
        """`obs`: what the agent's state S_i holds (its task's: None for a compound agent with no joint)."""
        self.topo, self.id = topo, agent_id
        self.spec = topo.agents[agent_id]
        self.geom = geometry_of(topo)
        self.is_root = self.spec.parent is None
        # The paper's neighbourhood: an agent sees the agents one level below it (its DOF children).
        self.visible = [c for c in self.spec.children if topo.agents[c].has_dof]
        self.leaves = topo.subtree_leaves(agent_id)
        self.action_rad = action_rad
        self.task: AgentTask = task.agent(agent_id, obs)
        n_task_vars = len(task.state_variables(agent_id))
        self.extra_names: tuple[str, ...] = ()  # the run's extra variables, after the task's
        self.unsigned_g3, self.state_kind = False, ""
        if obs is not None:
            self.extra_names = tuple(v.name for v in obs.extra_state[n_task_vars:])
            self.unsigned_g3 = obs.g3 == "unsigned"
            self.state_kind = obs.state

    # -- the top-down pass -------------------------------------------------------------------------
    def begin(self, head: Task | Down, q: float, own: Readings) -> TopDown:
        """The step begins: `head` is the task observation at the root, the parent's `Down` elsewhere; `q` the
        joint's encoder reading (0 for no joint), `own` its own readings (Obs.sense)."""
        children: Mapping[str, tuple[Coords, float | None, Readings]]
        if isinstance(head, Task):  # the root: the world's base; its task turns the observation into the reward
            h = self.task.head(head)
            base, goal, reward, context, children = self.topo.base, h.goal, h.reward, h.context, h.children
        else:
            base, goal, reward, context, children = head.base, head.goal, head.reward, head.sense, {}
        frame = self.geom.joint_frame(self.spec, base, q)
        end = self.geom.link_end(self.spec, frame)
        return TopDown(frame, end, q, goal, reward, context, children, {**context, **own} if own else context)

    def down(self, b: TopDown, child: str, epoch: int, step: int, base: Coords) -> Down:
        """What `child` is sent: its base frame, and the goal, r(t-1) and context (the root's task may give each child
        its own)."""
        goal, reward, context = b.children.get(child, (b.goal, b.reward, b.context))
        return Down(epoch=epoch, step=step, base=base, goal=goal, reward=reward, sense=context)

    # -- the bottom-up pass ------------------------------------------------------------------------
    def finish(
        self,
        b: TopDown,
        epoch: int,
        step: int,
        ups: Mapping[str, Up],
        last: int | None,
        tips_below: Mapping[str, Coords] | None = None,
    ) -> tuple[dict[str, Coords], StepView]:
        """Every awaited child's `up` is in (a leaf's at once): the subtree's tips and the agent's view of the step.
        `last`: its own action at the step before, if it took one; `tips_below`: tips it computed itself (a stand-in's
        for lost leaves)."""
        if self.spec.is_leaf:
            tips = {self.id: self.geom.tip(self.spec, b.end)}
        else:
            tips = dict(tips_below) if tips_below else {}
            for m in ups.values():
                tips.update(m.tips)
        tip = self.geom.centroid([tips[leaf] for leaf in self.leaves if leaf in tips])
        return tips, StepView(epoch, step, b.frame, b.end, tip, b.goal, b.sense, ups, last, b.q)

    def up(self, view: StepView, tips: dict[str, Coords]) -> Up:
        """What the parent gets: the subtree's tips, this agent's action of t-1 and its task's aggregate."""
        last = view.last_action
        return Up(
            epoch=view.epoch, step=view.step, tips=tips, action=-1 if last is None else last, sense=self.task.up(view)
        )

    # -- what the learner decides from -------------------------------------------------------------
    def decide_from(self, b: TopDown, view: StepView) -> Decision:
        """S_i, the reward, the moves to leave out and the action's scale."""
        tip, goal = view.tip, self.task.aim(view)  # the goal as its task has the agent aim (the task's, by default)
        s = self.geom.state(self.spec, b.frame, b.q, tip, goal, self.unsigned_g3, self.state_kind)
        values = self.task.state(view)
        if self.extra_names:  # the learner's own extra variables: from my geometry, else from my readings
            local = {**b.sense, **self.geom.extras(self.extra_names, b.frame, tip, goal)}
            values += [local.get(n, 0.0) for n in self.extra_names]
        if values:
            s = np.concatenate([s, values])
        return Decision(s, self.task.reward(view, b.reward), self.task.avoid(view), self.task.scale(view))

    def delta(self, action: int, scale: float) -> float:
        """The joint's increment for `action` (radians; metres for a prismatic joint)."""
        delta = (action - KEEP) * self.action_rad
        if scale != 1.0:
            delta *= scale
        return delta


def visible_actions(visible: list[str], actions: Mapping[str, int], lost: frozenset[str] = frozenset()) -> list[int]:
    """The visible children's actions for fictitious play's counts: a lost child's joint held, so to its parent it
    chose "keep"; one whose action is not known is -1 (the transition is then dropped)."""
    return [KEEP if c in lost else actions.get(c, -1) for c in visible]


def robot_passes(
    agents: Mapping[str, AgentPasses],
    order: Sequence[str],
    head: Task,
    q: Mapping[str, float],
    sense: Mapping[str, Readings],
    epoch: int,
    step: int,
    last: Mapping[str, int],
) -> tuple[dict[str, TopDown], dict[str, StepView]]:
    """One step's two passes over the whole robot in one place, as the agents compute them apart (a plain loop's step:
    the driver, swarm.py): top-down in the topology's `order` from the root's task observation `head`, bottom-up in
    reverse. `q`, `sense`: each joint's reading and own readings; `last`: each agent's action at
    the step before. Returns every agent's `TopDown` and `StepView`."""
    top: dict[str, TopDown] = {}
    for a in order:  # the top-down pass
        st = agents[a]
        parent = st.spec.parent
        if parent is not None:
            head = agents[parent].down(top[parent], a, epoch, step, top[parent].end)  # type: ignore[assignment]
        top[a] = st.begin(head, q.get(a, 0.0), sense.get(a, {}))
    ups: dict[str, Up] = {}
    views: dict[str, StepView] = {}
    for a in reversed(order):  # the bottom-up pass
        st = agents[a]
        tips, views[a] = st.finish(top[a], epoch, step, {c: ups[c] for c in st.spec.children}, last.get(a))
        if st.spec.parent is not None:
            ups[a] = st.up(views[a], tips)
    return top, views
