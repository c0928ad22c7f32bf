"""`[learner] plasticity = "direction"`: an agent finds which way its own motor turns from its own encoder; it reads
only the agent's own command and encoder, so its decisions are the same whether a fault is announced (a scenario's
event, recorded) or the body just changed with no word to anyone."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT
from kinswarm.actors.files.checkpoint import save_checkpoint
from kinswarm.actors.files.runfile import load_run
from kinswarm.actors.learning.learner import Learner
from kinswarm.actors.learning.plasticity import MotorDirection
from kinswarm.actors.learning.settings import PLASTICITY, LearnerSettings
from kinswarm.actors.run.inprocess import InProcessRun
from kinswarm.actors.step.learned import checkpoint_meta, restore_learner
from kinswarm.sim import kinematics


def test_a_checkpoint_of_the_removed_surprise_gate_loads_with_its_fields_ignored(tmp_path: Path) -> None:
    """Runs trained with the surprise gate (measured and removed: docs/notebook/adapt.md) hold its two fields beside
    the learner's own: `--from` such a run starts from its Q-values and counts, and the gate's fields are dropped."""
    trained = Learner(LearnerSettings(), 1, 0)
    rng = np.random.default_rng(1)
    for _ in range(50):
        trained.step(rng.random(6), float(rng.normal()), [1])
    old = {**trained.state_dict(), "surprise_usual": np.array(0.7), "surprise_seen": np.array(250, dtype=np.int64)}
    meta = checkpoint_meta("a1", "fuzzy", "chain4", 0, 0, 0)
    save_checkpoint(tmp_path / "a1.npz", old, meta)
    for plasticity in PLASTICITY:
        learner = Learner(LearnerSettings(plasticity=plasticity), 1, 0)
        assert restore_learner(learner, tmp_path / "a1.npz", "a1", "fuzzy") == 1
        state = learner.state_dict()
        assert not {"surprise_usual", "surprise_seen"} & set(state)
        assert np.array_equal(state["phi"], trained.state_dict()["phi"])
        assert np.array_equal(state["counts"], trained.counts)


def test_the_setting_is_checked() -> None:
    for removed in ("always", "surprise"):
        with pytest.raises(ValueError, match=f"plasticity must be one of off, direction, got '{removed}'"):
            LearnerSettings(plasticity=removed)
    with pytest.raises(ValueError, match="reads the joint angle q, which the turn state has not"):
        LearnerSettings.for_turn(plasticity="direction")


def _drive(motor: MotorDirection, q: float, moves: int, gain: float, rng: np.random.Generator) -> float:
    """`moves` steps of a joint whose motor turns `gain` x the command it is sent; returns the angle it ends at."""
    for _ in range(moves):
        meant = int(rng.integers(0, 3))
        motor.meant(meant)
        q += gain * (motor.command(meant) - 1) * 0.01
        motor.sees(q)
    return q


def test_the_motor_direction_turns_round_on_a_reversed_motor_and_holds_on_a_sound_or_locked_one() -> None:
    motor, rng = MotorDirection(), np.random.default_rng(0)
    q = _drive(motor, 0.0, 300, 1.0, rng)
    assert (motor.sign, motor.agree) == (1, pytest.approx(1.0))  # a sound motor: every move as meant
    q = _drive(motor, q, 5, -1.0, rng)
    assert motor.sign == 1  # a few moves the other way are not enough
    q = _drive(motor, q, 60, -1.0, rng)
    assert motor.sign == -1  # reversed: it now sends the opposite command ...
    assert [motor.command(a) for a in range(3)] == [2, 1, 0]
    q = _drive(motor, q, 200, -1.0, rng)
    assert motor.sign == -1 and motor.agree > 0.9  # ... and the moves are as meant again
    agree = motor.agree
    _drive(motor, q, 200, 0.0, rng)  # locked: the joint does not move, which says nothing of its direction
    assert (motor.sign, motor.agree) == (-1, agree)
    motor.reset_episode()  # no change of angle spans a reset of the pose
    motor.meant(2)
    motor.sees(3.0)
    assert motor.agree == agree


def test_a_learner_means_its_moves_and_sends_them_through_its_motor() -> None:
    learner = Learner(LearnerSettings(plasticity="direction"), 0, 0)
    learner.motor.sign = -1
    s = np.zeros(6)
    sent = learner.decide(s, None, avoid=(0,))  # a wall refused sending 0: the move meant by 2
    assert sent != 0 and learner._own == 2 - sent
    assert learner.state_dict()["motor_sign"] == -1


class ReversedA1(kinematics.ModelWorld):
    """The planar chain with a1's motor wired backwards inside the body: no fault, no event, nobody told."""

    def apply_increments(self, deltas: Mapping[str, float]) -> dict[str, float]:
        return super().apply_increments({a: -d if a == "a1" else d for a, d in deltas.items()})


def _plastic(learner: Learner) -> tuple:
    """What the mechanism decided: the motor's direction and agreement."""
    return learner.motor.sign, learner.motor.agree


def _decisions(tmp_path: Path, scenario: Path | None, world_cls: type, mode: str) -> tuple[list, list]:
    """A learning swarm with the mechanism on, 3 epochs: each epoch's final error and what the mechanism of each agent
    decided by each epoch's end; and the events the run recorded."""
    cfg = load_run(ROOT / "examples" / "chain4.toml", ["run.steps=150", "run.seed=3", f'learner.plasticity="{mode}"'])
    cfg = dataclasses.replace(cfg, out=str(tmp_path), scenario=str(scenario) if scenario else None)
    topo = cfg.topo()
    run = InProcessRun(cfg, topo, world=world_cls(topo))
    events: list = []
    factors: list = []
    errors: list = []
    try:
        for epoch in range(3):
            done = run.epoch(epoch, lambda *e: events.append(e))
            errors.append(done.final_error)
            factors.append([_plastic(run.learners[a]) for a in sorted(run.learners)])
    finally:
        run.close()
    return [errors, factors], events


@pytest.mark.parametrize("mode", ["direction"])
def test_the_mechanism_decides_the_same_whether_or_not_the_fault_was_announced(mode: str, tmp_path: Path) -> None:
    scenario = tmp_path / "reverse.toml"
    scenario.write_text('name = "a1 reversed"\n\n[[event]]\nstep = 0\nepoch = 0\nfault = "reverse"\ntarget = "a1"\n')
    announced, events = _decisions(tmp_path / "announced", scenario, kinematics.ModelWorld, mode)
    silent, none = _decisions(tmp_path / "silent", None, ReversedA1, mode)
    intact, _ = _decisions(tmp_path / "intact", None, kinematics.ModelWorld, mode)
    assert events and not none  # one run was told (an event recorded), the other not
    assert announced == silent  # the same errors and the same decisions of the mechanism, to the bit
    assert intact != announced  # the reversal changed what the robot and the mechanism did: not vacuous
    if mode == "direction":  # a1 found its motor reversed, the others kept theirs
        assert [sign for sign, _ in announced[1][-1]] == [-1, 1, 1, 1]
