"""Learner kinds (`[learner] kind`): the paper's fuzzy learner, independent learners (no model of the children) and a
tabular learner (no fuzzy interpolation), each held to what it claims to be, each run through the swarm."""

from __future__ import annotations

import copy
import json
import re
from pathlib import Path

import numpy as np
import pytest
from conftest import EXAMPLES, LOCKSTEP_ARGS, free_port, run_config, swarm_pids
from kinswarm.actors.cli.commands import main as cli_main
from kinswarm.actors.files.runfile import learner_settings, task_of
from kinswarm.actors.learning import jasm
from kinswarm.actors.learning.fleet import EPISODE, LearnerLane
from kinswarm.actors.learning.fuzzy import centres
from kinswarm.actors.learning.independent import IndependentLearner
from kinswarm.actors.learning.kinds import JointLearner
from kinswarm.actors.learning.learner import Learner
from kinswarm.actors.learning.settings import LearnerSettings
from kinswarm.actors.learning.tabular import TabularLearner
from kinswarm.actors.policies.registry import KINDS, kinds, learner_kind
from kinswarm.actors.step.seed import agent_seed
from test_faults import Run

pytestmark = pytest.mark.timeout(240)
CHAIN4 = EXAMPLES / "chain4.toml"
OTHER_KINDS = ("independent", "tabular")


def _settings(agent: str = "a2") -> LearnerSettings:
    cfg = run_config(CHAIN4)
    return learner_settings(task_of(cfg), cfg.learner, cfg.source)[agent]


def _states(settings: LearnerSettings, n: int, seed: int) -> np.ndarray:
    """States across (and a little beyond) every variable's range: the clipped ends are cells too."""
    rng = np.random.default_rng(seed)
    lo, hi = np.array(settings.state_ranges).T
    return rng.uniform(lo - 0.1 * (hi - lo), hi + 0.1 * (hi - lo), size=(n, len(lo)))


# -- the registry --------------------------------------------------------------------------------------------------
def test_every_kind_is_a_joint_learner_and_fuzzy_is_the_papers():
    assert kinds()[0] == "fuzzy" and set(kinds()) == {"fuzzy", "independent", "tabular", "onnx"}
    for name in (k for k in kinds() if not KINDS[k].takes):  # onnx needs its files: tests/test_onnx_policy.py
        learner = learner_kind(name).build(_settings(), 1, 0)
        assert isinstance(learner, JointLearner), name
    assert type(learner_kind("fuzzy").build(_settings(), 1, 0)) is Learner  # the paper's, not a copy of it
    with pytest.raises(
        ValueError, match="unknown learner kind 'neural'; expected one of fuzzy, independent, onnx, tabular"
    ):
        learner_kind("neural")


# -- tabular: a Q-table --------------------------------------------------------------------------------------------
class QTable:
    """Tabular Q-learning with the paper's joint action selection, written out in numpy: Q[cell] over joint actions
    (0 until updated), the TD rule of Eq. 5 on the entry of (s(t-1), joint action), E by Eq. 9, a(t) by Eq. 8."""

    def __init__(self, settings: LearnerSettings, n_visible: int, seed: list[int]) -> None:
        self.st, self.nv = settings, n_visible
        self.rng = np.random.default_rng(seed)
        self.q: dict[tuple[int, ...], np.ndarray] = {}
        self.counts = np.full((n_visible, 3), settings.count_prior)
        self.pending: tuple[tuple[int, ...], int] | None = None
        self.t = 0

    def cell(self, x: np.ndarray) -> tuple[int, ...]:
        """Per variable, the nearest set centre's index."""
        out = []
        for v, (m, (lo, hi)) in enumerate(zip(self.st.state_sets, self.st.state_ranges, strict=True)):
            c = centres(m, lo, hi)
            out.append(int(np.argmin(np.abs(c - min(max(x[v], lo), hi)))))
        return tuple(out)

    def row(self, cell: tuple[int, ...]) -> np.ndarray:
        return self.q.get(cell, np.zeros(3 ** (1 + self.nv)))

    def decide(self, x: np.ndarray, reward: float | None) -> int:
        st, cell = self.st, self.cell(x)
        P = jasm.probabilities(self.counts)
        T = jasm.temperature(self.t, st.T_max, st.s)
        if reward is not None and self.pending is not None:
            prev, joint = self.pending
            target = reward + st.gamma * jasm.expected_values(self.row(cell), P).max()  # Eq. 5
            q = self.q.setdefault(prev, np.zeros(3 ** (1 + self.nv)))
            q[joint] += st.lr * (target - q[joint])
        E = jasm.expected_values(self.row(cell), P)  # Eq. 9
        a = jasm.select_from_exponent((E - E.max()) / T, jasm.explore_probability(T, st.T_max, st.epsilon), self.rng)
        self.pending, self.t = (cell, a), self.t + 1
        return a

    def observe(self, visible: list[int]) -> None:
        self.counts[np.arange(self.nv), visible] += 1.0
        cell, a = self.pending  # type: ignore[misc]
        joint = a
        for b in visible:
            joint = joint * 3 + b
        self.pending = (cell, joint)


def test_the_tabular_learner_is_a_q_table_over_the_grid():
    """Step for step the same actions and the same table as the Q-table written out in numpy: one entry per visited
    cell, updated by the whole TD error: no interpolation between cells."""
    settings = _settings()
    learner, table = TabularLearner(settings, 1, agent_seed(0, "a2")), QTable(settings, 1, agent_seed(0, "a2"))
    learner.start_epoch(0)
    rng = np.random.default_rng(7)
    # few states, visited again and again (a table learns nothing from a cell seen once)
    pool = _states(settings, 12, seed=3)
    for t in range(600):
        x = pool[rng.integers(len(pool))] + rng.normal(0.0, 1e-3, size=pool.shape[1])
        reward = None if t == 0 else float(rng.normal())
        assert learner.decide(x, reward) == table.decide(x, reward), t
        seen = [int(rng.integers(3))]
        learner.observe(seen)
        table.observe(seen)
    d = learner.state_dict()
    grid = tuple(learner.fuzzy.n_sets)
    cells = {tuple(int(i) for i in np.unravel_index(k, grid)): r for k, r in zip(d["phi_keys"], d["phi"], strict=True)}
    assert cells.keys() == table.q.keys() and len(cells) > 5
    for cell, row in table.q.items():
        assert np.array_equal(cells[cell], row), cell
    assert np.array_equal(d["counts"], table.counts)


def test_a_tabular_state_fires_one_rule_of_weight_one():
    settings = _settings()
    learner = TabularLearner(settings, 0, 0)
    for x in _states(settings, 200, seed=5):
        rules, strength = learner.fuzzy.activate(learner.centre(x))
        assert rules.tolist() == [int(np.ravel_multi_index(learner.cell(x), tuple(learner.fuzzy.n_sets)))]
        assert strength[0] / strength.sum() == 1.0


# -- independent: no model of the children -------------------------------------------------------------------------
def test_an_independent_learner_is_the_papers_learner_of_a_leaf_whatever_its_children_do():
    """Its Q is over its own 3 actions; it learns what the fuzzy learner of an agent with no visible children learns
    from the same states and rewards, however the children act, and keeps no counts."""
    settings = _settings()
    ind, leaf = IndependentLearner(settings, 2, 11), Learner(settings, 0, 11)
    ind.start_epoch(0)
    leaf.start_epoch(0)
    rng = np.random.default_rng(2)
    for t, x in enumerate(_states(settings, 300, seed=9)):
        reward = None if t == 0 else float(rng.normal())
        assert ind.decide(x, reward) == leaf.decide(x, reward), t
        ind.observe([int(rng.integers(3)), int(rng.integers(3))])  # ignored
        leaf.observe([])
    a, b = ind.state_dict(), leaf.state_dict()
    assert a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a)
    assert a["phi"].shape[1] == 3 and a["counts"].shape == (0, 3) and ind.rules_used > 0


# -- fleets: every kind shares its lanes ---------------------------------------------------------------------------
@pytest.mark.parametrize("name", OTHER_KINDS)
def test_each_kinds_lanes_learn_as_one_learner(name):
    """A fleet's lanes (learning/fleet.py) over a learner of this kind compute what one learner of it computes with
    each lane's own transition, call by call, robots interleaved."""
    settings = _settings("a3")
    shared = learner_kind(name).build(settings, 1, agent_seed(0, "a3"))
    lanes = [LearnerLane(shared) for _ in range(3)]  # type: ignore[arg-type]
    rng = np.random.default_rng(1)
    for lane in lanes:
        lane.start_epoch(0)
    states = _states(settings, 8, seed=4)
    for t in range(40):
        for lane in lanes:
            state = states[rng.integers(len(states))]
            reward = None if t == 0 else float(rng.normal())
            one = copy.deepcopy(shared)
            for field in EPISODE:
                setattr(one, field, copy.deepcopy(lane._own_state[field]))
            one._rules_and_O = [(one._fired[i, 0], one._w[i]) for i in (0, 1)]
            one._fired[one._latest, 1] = one.q.lookup(one._fired[one._latest, 0])
            sel, nv = one._selection, one.n_visible
            one.counts, one._P, one._E, one._z = sel[:nv], sel[nv : 2 * nv], sel[2 * nv], sel[2 * nv + 1]
            assert lane.decide(state, reward) == one.decide(state, reward)
            seen = [int(rng.integers(0, 3))]
            one.observe(seen)
            lane.observe(seen)
            assert np.array_equal(shared.q.phi, one.q.phi) and np.array_equal(shared.counts, one.counts)
            assert lane._own_state["_pending"] == one._pending
    assert shared.rules_used > 0


# -- through the swarm ---------------------------------------------------------------------------------------------
def _run(tmp_path: Path, name: str, *args: str) -> dict:
    out = tmp_path / name
    argv = ["run", str(CHAIN4), "--out", str(out), "--listen", f"tcp/127.0.0.1:{free_port()}", "--no-progress"]
    assert cli_main([*argv, *LOCKSTEP_ARGS, *args]) == 0
    return json.loads((out / "summary.json").read_text())


@pytest.mark.parametrize("name", OTHER_KINDS)
def test_each_kind_runs_the_same_in_both_placements(tmp_path, name):
    common = ("--epochs", "2", "--steps", "100", "--seed", "3", "--set", f"learner.kind={name}")
    a = _run(tmp_path, "s", "--placement", "single", *common)
    b = _run(tmp_path, "p", "--placement", "process", *common)
    assert len(a["final_error"]) == 2 and a["final_error"] == b["final_error"]
    assert b["missed_cmds"] == 0
    fuzzy = _run(tmp_path, "f", "--placement", "single", "--epochs", "2", "--steps", "100", "--seed", "3")
    assert fuzzy["final_error"] != a["final_error"]  # another learner: another run
    header = json.loads(bytes(np.load(tmp_path / "p" / "agents" / "a2.npz")["__meta__"]).decode())
    assert header["learner"] == name  # the checkpoint says whose state it is
    assert swarm_pids(str(tmp_path / "p")) == []


def test_a_fleet_runs_each_kind(tmp_path):
    for name in OTHER_KINDS:
        s = _run(tmp_path, name, "--placement", "single", "--epochs", "2", "--steps", "60", "--set", "run.fleet=2",
                 "--set", f"learner.kind={name}")  # fmt: skip
        assert len(s["fleet_final_error"]) == 2 and all(len(row) == 2 for row in s["fleet_final_error"])


# independent is the paper's Learner with no visible agent (the same state, checkpointed by the same code as fuzzy's,
# whose kill and restore tests/test_faults.py runs in the default suite): its ~35 s run is in the slow suite, and
# tabular's (~70 s on a loaded machine) with it
@pytest.mark.timeout(600)
@pytest.mark.parametrize(
    "name", [pytest.param("independent", marks=pytest.mark.slow), pytest.param("tabular", marks=pytest.mark.slow)]
)
def test_a2_killed_mid_run_is_restored_from_its_checkpoint(tmp_path, name):
    """`kinswarm fault RUN kill a2` on a live run: a2 is restarted and restores its newest checkpoint (the state it
    restored hashes as the checkpoint did), and the run goes on to its end. A restart loads the compiled kernel anew
    (seconds; tens of them on a busy 2-core machine), so the run is long and the wait for it generous."""
    run = Run(tmp_path, CHAIN4, "--epochs", "80", "--steps", "100", "--seed", "5", "--set", f"learner.kind={name}")
    run.wait_epochs(2)
    r = run.fault("kill", "a2")
    assert r.returncode == 0 and "kill: a2" in r.stdout, r.stderr
    restored = run.wait_event("restored", "a2", timeout=240.0)["detail"]
    code, text = run.finish(timeout=400.0)
    assert code == 0, text
    m = re.search(r"checkpoint sha256=(\w+) restored sha256=(\w+)", restored)
    assert m and m.group(1) == m.group(2), restored  # from its checkpoint, not from scratch
    s = run.summary()
    assert len(s["final_error"]) == 80 and s["restarts"] == {"a1": 0, "a2": 1, "a3": 0, "a4": 0}
    assert swarm_pids(str(run.out)) == []


# -- bad input ---------------------------------------------------------------------------------------------------
def _refused(tmp_path: Path, capsys: pytest.CaptureFixture[str], *args: str) -> str:
    out = tmp_path / "x"
    assert cli_main(["run", str(CHAIN4), "--out", str(out), "--no-progress", *args]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("kinswarm: error: ") and "\n" not in err and "Traceback" not in err, err
    assert not out.exists()  # refused before anything was made
    return err


def test_an_unknown_kind_is_one_line_naming_the_known_ones(tmp_path, capsys):
    err = _refused(tmp_path, capsys, "--set", "learner.kind=neural")
    assert "learner.kind" in err and "'neural'" in err and "fuzzy, independent, onnx, tabular" in err, err


@pytest.mark.parametrize(("name", "field"), [(k, f) for k in OTHER_KINDS for f, _ in KINDS[k].refuses])
def test_a_kind_given_a_setting_it_does_not_take_is_one_line_naming_both(tmp_path, capsys, name, field):
    value = {"slope": "3.0", "top_k": "1", "count_prior": "2.0", "count_freeze": "3"}[field]
    err = _refused(tmp_path, capsys, "--set", f"learner.kind={name}", "--set", f"learner.{field}={value}")
    assert f"learner.{field}" in err and f"the {name} learner does not take it" in err, err


def test_a_setting_at_its_default_asks_nothing_of_a_kind():
    """`count_freeze = 0` (never) in a file run with the independent kind: nothing is asked of it, so it is taken
    (examples/grasp3-sensed.toml freezes the counts; the grasp experiment runs it with each kind)."""
    kind = KINDS["independent"]
    assert kind.refused({"count_freeze": 0, "lr": 0.5}) is None
    assert kind.refused({"count_freeze": 50}) is not None and "count_freeze" in kind.refused({"count_freeze": 50})


def test_a_checkpoint_of_another_kind_is_refused(tmp_path, capsys):
    _run(tmp_path, "fz", "--placement", "single", "--epochs", "1", "--steps", "20")
    err = _refused(tmp_path, capsys, "--from", str(tmp_path / "fz"), "--set", "learner.kind=tabular")
    assert "'fuzzy' learner" in err and "'tabular'" in err, err
