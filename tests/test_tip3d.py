"""reach3d's `tip = "sensed"` on a robot from URDF (the iiwa): where the tool point the agents compute from their
encoders disagrees with the sensed one, they aim by the sensed one. As on the planar chain (test_tip.py): on a sound
arm the run is the same to the bit with it on and off, and its decisions are the same whether an encoder's offset is
announced (a scenario's event) or the encoder just reads wrong."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import pytest
from conftest import ROOT
from kinswarm.actors.files.runfile import load_run
from kinswarm.actors.run.inprocess import InProcessRun
from kinswarm.actors.tasks import reach3d, sensed
from kinswarm.actors.tasks.base import StepView
from kinswarm.protocol.spec import SpecError
from kinswarm.sim.world import World
from sensed_runs import same, watched

OFFSET = math.radians(10.0)
POINT = "task.goal=[0.45, 0.3, 0.55]"
POSE = "task.goal=[0.5, 0.1, 0.5, 180, 0, 0]"


class OffsetA2(World):
    """The iiwa with its shoulder's (a2) encoder reading +10° inside the body: no fault, no event, nobody told."""

    def joint_positions(self) -> dict[str, float]:
        q = super().joint_positions()
        return {**q, "a2": q["a2"] + OFFSET}


def _run(tmp_path: Path, tip: str, goal: str = POINT, scenario: Path | None = None, silent: bool = False) -> tuple:
    """A learning swarm on the iiwa, 2 epochs of 40 steps, aiming as `tip` says: every step's error, what each agent's
    aim moved the goal by at each step (the mechanism's decisions), every agent's Q-values and counts at the end; and
    the events the run recorded."""
    cfg = load_run(ROOT / "examples" / "iiwa.toml", ["run.steps=40", "run.seed=3", goal, f'task.tip="{tip}"'])
    cfg = dataclasses.replace(cfg, out=str(tmp_path), scenario=str(scenario) if scenario else None)
    topo = cfg.topo()
    run = InProcessRun(cfg, topo, world=OffsetA2(topo) if silent else None)
    return watched(run, 2)


def test_the_mechanism_decides_the_same_whether_or_not_the_offset_was_announced(tmp_path: Path) -> None:
    scenario = tmp_path / "offset.toml"
    scenario.write_text(
        'name = "a2 reads +10"\n\n[[event]]\nstep = 0\nepoch = 0\nfault = "offset"\ntarget = "a2"\ndegrees = 10.0\n'
    )
    announced, events = _run(tmp_path / "announced", "sensed", scenario=scenario)
    silent, none = _run(tmp_path / "silent", "sensed", silent=True)
    assert events and not none  # one run was told (an event recorded), the other not
    assert same(announced, silent)
    # every agent aimed elsewhere than the goal at every step: a2's +10° carries the tool ~ 2 r sin 5° (r ~ 0.7 m)
    assert min(math.hypot(*d) for d in announced[1]) > 10 * sensed.TIP_PRECISION
    off, _ = _run(tmp_path / "off", "computed", scenario=scenario)
    assert off[0] != announced[0]  # aiming by the sensed tool point changed what the arm did: not vacuous
    assert not any(any(d) for d in off[1])  # off, every agent aims at the goal itself


@pytest.mark.parametrize("goal", [POINT, POSE], ids=["point", "pose"])
def test_on_a_sound_arm_the_run_is_the_same_to_the_bit_with_it_on_and_off(goal: str, tmp_path: Path) -> None:
    on, _ = _run(tmp_path / "on", "sensed", goal)
    off, _ = _run(tmp_path / "off", "computed", goal)
    assert same(on, off)
    assert not any(any(d) for d in on[1])  # it never moved an aim


def test_a_pose_goal_moves_its_point_and_keeps_its_orientation() -> None:
    """The aim is the goal's point moved by (computed - sensed); the orientation (a quaternion) stays."""
    settings = reach3d.Reach3dSettings(goal=(0.5, 0.1, 0.5, 180.0, 0.0, 0.0), tip="sensed")
    agent = reach3d.Reach3dAgent(settings, None, ("a7",))  # type: ignore[arg-type]
    goal = reach3d.wire_goal(settings.goal)  # type: ignore[arg-type]
    computed = (0.52, 0.08, 0.55, 0.0, 0.0, 0.0, 1.0)
    sense = {sensed.sensed_key("a7", a): v for a, v in zip("xyz", (0.50, 0.12, 0.54), strict=True)}
    view = StepView(0, 0, (0.0,) * 7, (0.0,) * 7, computed, goal, sense, {}, None)  # type: ignore[arg-type]
    aim = agent.aim(view)
    assert aim[:3] == pytest.approx((0.52, 0.06, 0.51))
    assert aim[3:] == goal[3:]
    assert agent.aim(dataclasses.replace(view, sense={})) == goal  # no sensed tip this step: the goal itself


def test_the_setting_is_checked() -> None:
    one_line = "--set task.tip=\"measured\": task.tip: 'measured' is not one of computed, sensed"
    with pytest.raises(SpecError, match=one_line):
        load_run(ROOT / "examples" / "iiwa.toml", ['task.tip="measured"'])
