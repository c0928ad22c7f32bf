"""The reach task's `tip = "sensed"`: where the tip the agents compute from their encoders disagrees with the sensed
one, they aim by the sensed one. It compares two tips the swarm has anyway, so its decisions are the same whether an
encoder's fault is announced (a scenario's event, recorded) or the encoder just reads wrong with no word to anyone;
on a sound robot the two tips agree, and the run is the same to the bit as with the setting off."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import pytest
from conftest import ROOT
from kinswarm.actors.files.runfile import load_run
from kinswarm.actors.run.inprocess import InProcessRun
from kinswarm.actors.tasks import reach
from kinswarm.actors.tasks.base import StepView
from kinswarm.actors.tasks.sensed import TIP_PRECISION, sensed_key
from kinswarm.protocol.spec import SpecError
from kinswarm.sim import kinematics
from sensed_runs import same, watched

OFFSET = math.radians(10.0)


class OffsetA1(kinematics.ModelWorld):
    """The planar chain with a1's encoder reading +10° inside the body: no fault, no event, nobody told."""

    def joint_positions(self) -> dict[str, float]:
        q = super().joint_positions()
        return {**q, "a1": q["a1"] + OFFSET}


def _run(tmp_path: Path, tip: str, scenario: Path | None = None, world_cls: type | None = None) -> tuple[list, list]:
    """A learning swarm on chain4, 3 epochs of 150 steps, aiming as `tip` says: every step's error and every agent's
    Q-values and counts at the end, what each agent's aim moved the goal by at each step (the mechanism's decisions),
    and the events the run recorded."""
    cfg = load_run(ROOT / "examples" / "chain4.toml", ["run.steps=150", "run.seed=3", f'task.tip="{tip}"'])
    cfg = dataclasses.replace(cfg, out=str(tmp_path), scenario=str(scenario) if scenario else None)
    topo = cfg.topo()
    run = InProcessRun(cfg, topo, world=world_cls(topo) if world_cls else None)
    return watched(run, 3)


def test_the_mechanism_decides_the_same_whether_or_not_the_fault_was_announced(tmp_path: Path) -> None:
    scenario = tmp_path / "offset.toml"
    scenario.write_text(
        'name = "a1 reads +10"\n\n[[event]]\nstep = 0\nepoch = 0\nfault = "offset"\ntarget = "a1"\ndegrees = 10.0\n'
    )
    announced, events = _run(tmp_path / "announced", "sensed", scenario, kinematics.ModelWorld)
    silent, none = _run(tmp_path / "silent", "sensed", None, OffsetA1)
    assert events and not none  # one run was told (an event recorded), the other not
    assert same(announced, silent)  # the same errors, aims and learning, to the bit
    moved = [math.hypot(*d) for d in announced[1]]
    # every agent aimed elsewhere than the goal at every step: the computed tip is off by 2 r sin 5° (r > 0.5 here)
    assert min(moved) > TIP_PRECISION
    off, _ = _run(tmp_path / "off", "computed", scenario, kinematics.ModelWorld)
    assert off[0] != announced[0]  # aiming by the sensed tip changed what the robot did: not vacuous
    assert not any(math.hypot(*d) for d in off[1])  # off, every agent aims at the goal itself


@pytest.mark.parametrize("world_cls", [None, kinematics.ModelWorld], ids=["pybullet", "model"])
def test_on_a_sound_robot_the_run_is_the_same_to_the_bit_with_it_on_and_off(world_cls: type | None,
                                                                             tmp_path: Path) -> None:  # fmt: skip
    """PyBullet's tips are single precision (the computed and sensed tips differ by < 1e-6 there): still within the
    sensor's precision, so nothing changes."""
    on, _ = _run(tmp_path / "on", "sensed", None, world_cls)
    off, _ = _run(tmp_path / "off", "computed", None, world_cls)
    assert same(on, off)
    assert not any(math.hypot(*d) for d in on[1])  # it never moved an aim


def test_aiming_at_the_moved_goal_brings_the_sensed_tip_to_the_goal() -> None:
    """The aim is the goal moved by (computed - sensed): the computed tip at the aim is the sensed one at the goal."""
    agent = reach.ReachAgent(reach.ReachSettings(goal=(4.0, 6.0), tip="sensed"), ("a4",))
    computed, sensed, goal = (5.0, 5.5), (4.2, 5.9), (4.0, 6.0)
    sense = {sensed_key("a4", "x"): sensed[0], sensed_key("a4", "y"): sensed[1]}
    view = StepView(0, 0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), computed, goal, sense, {}, None)
    aim = agent.aim(view)
    assert aim == pytest.approx((goal[0] + 0.8, goal[1] - 0.4))
    assert (aim[0] - computed[0], aim[1] - computed[1]) == pytest.approx((goal[0] - sensed[0], goal[1] - sensed[1]))
    # no sensed tip this step (a lost leaf's): nothing to compare, the goal itself
    assert agent.aim(dataclasses.replace(view, sense={})) == goal


def test_the_setting_is_checked() -> None:
    one_line = "--set task.tip=\"measured\": task.tip: 'measured' is not one of computed, sensed"
    with pytest.raises(SpecError, match=one_line):
        load_run(ROOT / "examples" / "chain4.toml", ['task.tip="measured"'])
