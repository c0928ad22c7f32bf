"""The driver of the step: a run's agents, their learners and its robot stepped in one place, as every placement
computes them. The inprocess placement (actors/run/inprocess.py) is a short loop over `Swarm`; the env faces
(actors/env/core.py) step it with their caller's actions in place of the learners; the agent actor takes one joint's
pieces (`agent_learner`, `start_epoch`, `learn_and_decide`, `observe_children`, `drop_transition`) and the simulator
actor the robot's (`faults_due`). So a run gives the same numbers wherever its agents live.

One epoch, as the inprocess loop runs it:

    swarm.start_epoch(epoch, learners, trained)          # every agent's task, every learner's schedule
    last = {}                                            # each agent's action at the step before
    for t in range(steps):
        events = swarm.faults(robot, epoch)              # the scenario's joint faults due at this step, applied
        step = swarm.passes(robot, epoch, last)          # top-down, bottom-up: one Decision per joint
        acted = swarm.learn_and_decide(step, learners, last, traces)  # each joint, leaves first
        last = actions(acted)
        robot.move(commands(robot, acted))
    swarm.close_epoch(learners, last)                    # the children's actions at the epoch's last step

One joint, in every placement (`learn_and_decide`): its visible children's actions at the step before go into its
counts (or, one not known, the transition is dropped), its learner learns from r(t-1) and chooses a(t) on S_i
(`learner.decide`), the trace records them, a joint with no visible children completes its joint action at once, and
a(t) becomes the joint's increment.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from kinswarm.actors.files.runfile import kind_of, learner_settings, task_of
from kinswarm.actors.learning.kinds import JointLearner
from kinswarm.actors.learning.settings import LearnerSettings
from kinswarm.actors.policies.registry import LearnerKind
from kinswarm.actors.tasks.base import StepView
from kinswarm.protocol.messages import Fault
from kinswarm.protocol.topology import Topology

from .passes import AgentPasses, Decision, TopDown, robot_passes, visible_actions
from .seed import agent_seed
from .trace import StepTrace

if TYPE_CHECKING:  # the robot is duck-typed here: an agent's process loads no physics engine for this module
    from kinswarm.actors.files.config import RunConfig
    from kinswarm.sim.robot import Event, Robot

Acted = dict[str, tuple[int, float]]  # joint -> (a(t), the joint's increment, before the robot clips it)


# -- one joint -----------------------------------------------------------------------------------------------------
def agent_learner(
    cfg: RunConfig, topo: Topology, agent: str, kind: LearnerKind, settings: LearnerSettings
) -> JointLearner:
    """`agent`'s learner as the run builds it in every placement: its kind over its settings, its visible children,
    its one seed (seed.py) and its place in the robot's DOF order."""
    spec = topo.agents[agent]
    n_visible = sum(topo.agents[c].has_dof for c in spec.children)
    index = topo.dof_agents.index(agent)
    return kind.build(settings, n_visible, agent_seed(cfg.seed, agent), agent=agent, index=index, options=cfg.learner)


def start_epoch(passes: AgentPasses, learner: JointLearner | None, trained: int, step: int = 0) -> None:
    """An agent's epoch begins at `step` (0; later for an agent restarted in mid-epoch): its task's epoch state, and
    its learner's schedule at `trained` epochs (those before the run, `--from`, and the run's so far)."""
    passes.task.start_epoch()
    if learner is not None:
        learner.start_epoch(trained, t=step)


def drop_transition(learner: JointLearner, step: int) -> None:
    """The learner's pending transition dropped and its schedule moved to `step`: the joint action it would complete
    is not known (a visible child's action lost, or steps missed), so no TD update spans it."""
    learner.resync(step)


def observe_children(learner: JointLearner, actions: Sequence[int], step: int, learn: bool) -> None:
    """The visible children's actions at the step before `step` into the learner (fictitious play's counts, the
    pending joint action); with one not known (-1: a child lost or restarted) the transition is dropped instead."""
    if all(0 <= b < learner.n_actions for b in actions):
        learner.observe(actions, learn=learn)
    else:
        drop_transition(learner, step)


def learn_and_decide(
    learner: JointLearner,
    passes: AgentPasses,
    d: Decision,
    children: Sequence[int] | None,
    epoch: int,
    step: int,
    learn: bool,
    explore: bool,
    trace: StepTrace | None,
) -> tuple[int, float]:
    """One joint's learning and decision at a step: `children`, its visible children's actions at the step before
    (None when none are awaited: the epoch's first step, a step after a gap), then the TD update with r(t-1) and
    a(t) on S_i (`d`, from `passes.decide_from`), the trace; a joint with no visible child completes its joint
    action at once. Returns a(t) and the joint's increment."""
    if children is not None:
        observe_children(learner, children, step, learn)
    action = learner.decide(d.state, d.reward, learn=learn, explore=explore, avoid=d.avoid)
    if trace is not None:
        trace.add(epoch, step, d.state, action, learner)
    if not passes.visible:
        learner.observe([], learn=learn)
    return action, passes.delta(action, d.scale)


# -- the robot -----------------------------------------------------------------------------------------------------
def faults_due(robot: Robot, epoch: int, apply: Callable[[Fault], Any]) -> list[Fault]:
    """The scenario's entries due at the robot's running step of `epoch`: each joint fault, in the scenario's order,
    handed to `apply` (the robot's own `apply_fault`; the simulator actor's, which also says it on the wire and
    keeps a fleet's robot to its own). Returns the others (process and link faults: the supervisor's to apply)."""
    joint, others = robot.due(epoch)
    for f in joint:
        apply(f)
    return others


def actions(acted: Acted) -> dict[str, int]:
    """Each joint's a(t): what its parent counts at the next step."""
    return {a: action for a, (action, _) in acted.items()}


def commands(robot: Robot, acted: Acted) -> dict[str, float]:
    """Each joint's increment as the robot takes it (clipped to the action size, as the simulator actor clips a
    `Cmd`)."""
    return {a: robot.clip(delta) for a, (_, delta) in acted.items()}


# -- the whole swarm -----------------------------------------------------------------------------------------------
@dataclass(slots=True)
class SwarmStep:
    """A step's passes over the whole robot: every agent's top-down pass and view, and what each joint decides
    from."""

    epoch: int
    t: int
    top: dict[str, TopDown]
    views: dict[str, StepView]
    decisions: dict[str, Decision]


class Swarm:
    """A run's agents in one place: their passes (`agents`), the joints that decide (`deciders`, leaves first, as the
    bottom-up pass reaches them), and the steps of a plain loop over them and a robot."""

    def __init__(self, cfg: RunConfig, topo: Topology) -> None:
        self.cfg, self.topo = cfg, topo
        self.task = task_of(cfg)
        self.settings: dict[str, LearnerSettings] = learner_settings(self.task, cfg.learner, cfg.source)
        self.kind: LearnerKind = kind_of(cfg.learner, cfg.source)
        self.order = list(topo.order)  # top-down: every parent before its children
        self.agents = {a: AgentPasses(topo, a, self.task, self._observation(a), cfg.action_rad) for a in self.order}
        self.deciders = [a for a in reversed(self.order) if a in self.settings]

    def _observation(self, agent: str) -> Any:
        """What the agent's S_i holds: its learner's observation (none for a compound agent with no joint)."""
        settings = self.settings.get(agent)
        return settings.observation if settings is not None else None

    def learners(self) -> dict[str, JointLearner]:
        """Every joint's learner, in the robot's DOF order, built as every placement builds it."""
        return {a: agent_learner(self.cfg, self.topo, a, self.kind, self.settings[a]) for a in self.topo.dof_agents}

    def start_epoch(
        self, epoch: int, learners: Mapping[str, JointLearner] | None = None, trained: Mapping[str, int] | None = None
    ) -> None:
        """Every agent's epoch `epoch` begins (its task's state), and every learner's, after the epochs it was
        `trained` before the run."""
        learners, trained = learners or {}, trained or {}
        for a in self.order:
            start_epoch(self.agents[a], learners.get(a), trained.get(a, 0) + epoch)

    def faults(self, robot: Robot, epoch: int) -> list[Event]:
        """The scenario's joint faults due at the robot's step, applied: their events. The others were refused before
        the run (a plain loop has no processes or links); a step past the epoch's last (the env's passes after its
        last move) has none: the swarm never reaches it."""
        events: list[Event] = []
        if robot.t < self.cfg.steps:
            faults_due(robot, epoch, lambda f: events.extend(robot.apply_fault(f)[0]))
        return events

    def passes(self, robot: Robot, epoch: int, last: Mapping[str, int]) -> SwarmStep:
        """The robot's step: its readings and the root's task observation, the top-down pass in the topology's
        order, the bottom-up pass in reverse (`last`: each agent's action at the step before), and what each joint
        decides from."""
        t = robot.t
        q, sense, head = robot.observations(epoch)
        top, views = robot_passes(self.agents, self.order, head, q, sense, epoch, t, last)
        decisions = {a: self.agents[a].decide_from(top[a], views[a]) for a in self.deciders}
        return SwarmStep(epoch, t, top, views, decisions)

    def learn_and_decide(
        self,
        step: SwarmStep,
        learners: Mapping[str, JointLearner],
        last: Mapping[str, int],
        traces: Mapping[str, StepTrace],
    ) -> Acted:
        """Each joint's learner, leaves first: its children's actions of the step before (`last`), then a(t)."""
        learn, explore = self.cfg.learn, self.cfg.explore
        acted: Acted = {}
        for a in self.deciders:
            st = self.agents[a]
            children = visible_actions(st.visible, last) if st.visible and step.t > 0 else None
            d, trace = step.decisions[a], traces.get(a)
            acted[a] = learn_and_decide(learners[a], st, d, children, step.epoch, step.t, learn, explore, trace)
        return acted

    def close_epoch(self, learners: Mapping[str, JointLearner], last: Mapping[str, int]) -> None:
        """After the epoch's last step: each joint's children's actions at that step, so its counts are whole before
        a checkpoint (the agents' closing `up`)."""
        for a in self.deciders:
            st = self.agents[a]
            if st.visible:
                observe_children(learners[a], visible_actions(st.visible, last), self.cfg.steps, self.cfg.learn)
