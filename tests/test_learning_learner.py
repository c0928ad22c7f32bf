"""Learner: settings validation, TD update through step(), counts, lr decay, checkpoints, memory."""

import numpy as np
import pytest
from kinswarm.actors.learning import Learner, LearnerSettings

S0 = np.array([0.1, 0.2, 3.0, 1.0, 2.0, 0.3])
S1 = np.array([0.4, -1.0, 6.0, -3.0, 2.0, -1.3])


def test_settings_validation_and_for_reach():
    st = LearnerSettings.for_reach(6.0, lr=0.2)
    assert st.ranges[2] == (0.0, 6.0) and st.ranges[3] == (-12.0, 12.0) and st.lr == 0.2
    for bad, match in [
        (dict(T_max=1.0), "T_max"),
        (dict(n_sets=(3, 3)), "n_sets"),
        (dict(top_k=8), "top_k"),
        (dict(ranges=((0, 1),) * 5 + ((1, 0),)), "ranges"),
        (dict(count_prior=0.0), "count_prior"),
        (dict(lr=0.0), "lr"),
        (dict(lr_anneal=(5, 5)), "lr_anneal"),
        (dict(lr_anneal=(6, 2)), "lr_anneal"),
        (dict(lr_anneal=(-1, 4)), "lr_anneal"),
        (dict(lr_anneal=(1.5, 4)), "lr_anneal"),
        (dict(lr_anneal=(4,)), "lr_anneal"),
        (dict(count_freeze=-1), "count_freeze"),
        (dict(count_freeze=2.0), "count_freeze"),
        (dict(count_freeze=True), "count_freeze"),
        (dict(extra_state=[{"name": "x", "sets": 0, "range": [0, 1]}]), "sets must be an int >= 1"),
        (dict(extra_state=[{"name": "x", "sets": 3, "range": [1, 0]}]), "lo < hi"),
        (dict(extra_state=[{"name": "x", "sets": 3}]), "missing .range."),
        (dict(extra_state=[{"name": "q", "sets": 3, "range": [0, 1]}]), "names must differ"),
        (dict(extra_state=[{"name": "x", "sets": 3, "range": [0, 1], "colour": 1}]), "unknown field 'colour'"),
    ]:
        with pytest.raises(ValueError, match=match):
            LearnerSettings(**bad)
    with pytest.raises(ValueError, match="reach"):
        LearnerSettings.for_reach(-1.0)


def test_td_update_through_step_hand_computed():
    st = LearnerSettings(lr=0.5)
    ln = Learner(st, n_visible=0, seed=0)
    ln.start_epoch(0)
    a0 = ln.step(S0, None, [])
    assert ln.rules_used == 0  # no reward yet: nothing learned
    ln.step(S1, 1.0, [])
    # phi = 0 everywhere: delta = lr (r + gamma * 0 - 0) = 0.5; phi^i[a0] = 0.5 O^i / sum O
    rules, O = ln.fuzzy.activate(S0)  # noqa: E741
    w = O / O.sum()
    Q = ln.q.q_values(rules, O)
    assert Q[a0] == pytest.approx(0.5 * np.sum(w * w))
    assert np.count_nonzero(Q) == 1
    assert ln.rules_used == 64


def test_counts_joint_index_and_lr_decay():
    st = LearnerSettings()
    ln = Learner(st, n_visible=2, seed=[3, 1])
    assert ln.n_joint == 27 and ln.joint_index(2, [1, 0]) == 2 * 9 + 1 * 3 + 0
    ln.start_epoch(0)
    ln.step(S0, None, [2, 0])
    np.testing.assert_allclose(ln.counts, [[1, 1, 2], [2, 1, 1]])
    ln.start_epoch(2)
    assert ln.t == 0 and ln.lr == pytest.approx(st.lr * (1 - st.lr_decay) ** 2)
    with pytest.raises(ValueError, match="visible"):
        ln.step(S0, None, [1])
    with pytest.raises(ValueError, match="visible action 3"):
        ln.step(S0, None, [1, 3])


def test_lr_anneal_ramps_to_zero_and_then_learns_nothing():
    """lr_anneal = (first, last): lr(epoch) as lr_decay gives it until `first`, then scaled linearly to 0 at `last`;
    from there on a learning step changes no phi (the policy a frozen swarm runs), though counts go on."""
    st = LearnerSettings(lr_anneal=[10, 20])  # a JSON list from --learner is accepted
    assert st.lr_anneal == (10, 20)
    ln = Learner(st, n_visible=1, seed=0)
    decayed = [st.lr * (1 - st.lr_decay) ** e for e in (0, 10, 15, 20, 30)]
    for epoch, expected in zip((0, 10, 15, 20, 30), [decayed[0], decayed[1], decayed[2] / 2, 0.0, 0.0], strict=True):
        ln.start_epoch(epoch)
        assert ln.lr == pytest.approx(expected)
    ln.step(S0, None, [1])
    ln.step(S1, 1.0, [2])
    ln.step(S0, 1.0, [2])
    assert ln.rules_used == 0  # lr 0: no TD update, not even the phi = 0 rows an update would allocate
    np.testing.assert_allclose(ln.counts, [[1, 2, 3]])
    restored = Learner(st, n_visible=1, seed=1)
    restored.load_state_dict(ln.state_dict())  # an annealed checkpoint (lr 0) loads
    assert restored.lr == 0.0


def test_count_freeze_stops_the_counts_not_the_td_updates():
    """count_freeze = N: the fictitious-play counts count in epochs before N and stay as they are from N on, while
    the TD updates go on (lr > 0)."""
    ln = Learner(LearnerSettings(count_freeze=3), n_visible=1, seed=0)
    ln.start_epoch(2)
    ln.step(S0, None, [2])
    np.testing.assert_allclose(ln.counts, [[1, 1, 2]])
    ln.start_epoch(3)
    ln.step(S0, None, [0])
    ln.step(S1, 1.0, [0])
    np.testing.assert_allclose(ln.counts, [[1, 1, 2]])
    assert ln.rules_used > 0  # learning went on
    ln.start_epoch(0)  # (a run --from an earlier epoch) counts again
    ln.step(S0, None, [0])
    np.testing.assert_allclose(ln.counts, [[2, 1, 2]])


@pytest.mark.parametrize("probe", ["act_from", "bootstrap", "tabu_memory", "grasp_state", "shield", "fine_action"])
def test_options_measured_and_not_kept_or_moved_to_a_task_are_gone(probe):
    """The learner is the paper's: probes that were measured and not kept, and task settings, are not accepted."""
    with pytest.raises(TypeError, match=probe):
        LearnerSettings(**{probe: 1})
    assert len(LearnerSettings.__dataclass_fields__) <= 20


def test_extra_state_variables_extend_the_state_in_order():
    from kinswarm.actors.learning.settings import StateVariable

    st = LearnerSettings(extra_state=[{"name": "g_perp", "sets": 7, "range": [-1.5, 1.5]}])
    assert st.extra_state == (StateVariable("g_perp", 7, (-1.5, 1.5)),)
    task = st.with_task_state((StateVariable("clearance", 5, (0.0, 1.0)),))
    assert task.state_names[6:] == ("clearance", "g_perp") and task.state_sets[6:] == (5, 7)


def test_greedy_ties_random_at_start():
    ln = Learner(LearnerSettings(), n_visible=1, seed=7)
    ln.start_epoch(0)
    picks = {ln.step(S0, None, [1], learn=False, explore=False) for _ in range(60)}
    assert picks == {0, 1, 2}


def _trained(seed=0, n=300):
    ln = Learner(LearnerSettings(), n_visible=1, seed=seed)
    rng = np.random.default_rng(seed)
    ln.start_epoch(0)
    r = None
    for _ in range(n):
        ln.step(S0 + rng.normal(size=6) * 0.3, r, [int(rng.integers(3))])
        r = float(rng.normal())
    return ln


def test_learn_off_changes_nothing_learned():
    """A frozen learner (learn=False) keeps phi, the fictitious-play counts and lr as trained: its choices are a
    fixed function of the state, whatever it met before (a test goal's result does not depend on the others)."""
    ln = _trained()
    before = ln.state_dict()
    rng = np.random.default_rng(3)
    for _ in range(200):
        ln.step(S0 + rng.normal(size=6) * 0.3, float(rng.normal()), [int(rng.integers(3))], learn=False, explore=False)
    for name, value in ln.state_dict().items():
        np.testing.assert_array_equal(value, before[name], err_msg=name)


def test_state_dict_round_trip_and_validation():
    ln = _trained()
    d = ln.state_dict()
    assert set(d) >= {"phi_keys", "phi", "counts", "lr", "epoch"}
    fresh = Learner(LearnerSettings(), n_visible=1, seed=1)
    fresh.load_state_dict(d)
    assert fresh.rules_used == ln.rules_used and fresh.epoch == ln.epoch and fresh.lr == ln.lr
    np.testing.assert_array_equal(fresh.counts, ln.counts)
    for s in (S0, S1):
        rules, O = ln.fuzzy.activate(s)  # noqa: E741
        np.testing.assert_allclose(fresh.q.q_values(rules, O), ln.q.q_values(rules, O))
    for field, bad in [
        ("counts", np.ones((2, 3))),
        ("phi", d["phi"][:, :3]),
        ("phi_keys", d["phi_keys"].astype(np.float64)),
        ("lr", np.array(2.0)),
        ("epoch", np.array(-1)),
    ]:
        with pytest.raises(ValueError, match=field):
            fresh.load_state_dict({**d, field: bad})
    with pytest.raises(ValueError, match="counts"):
        fresh.load_state_dict({k: v for k, v in d.items() if k != "counts"})


def test_dense_grid_never_allocated():
    ln = _trained(n=1000)
    dense = 1_783_600 * 9 * 8  # the full phi table would be ~128 MB
    assert ln.rules_used <= 64 * 1000
    assert ln.memory_bytes < dense / 20
    assert ln.q.phi.shape[0] < 1_783_600


def test_taking_turns_is_per_user_and_gives_way_where_no_lock_file_can_be_had(tmp_path, monkeypatch) -> None:
    """The compile's turn-taking lock: one file per user in the temporary directory, and a directory it cannot
    write (another user's file of the same name, a read-only /tmp) costs the turns, not the learner."""
    import os
    import tempfile

    from kinswarm.actors.learning.learner import _taking_turns

    monkeypatch.setattr(tempfile, "gettempdir", lambda: str(tmp_path))
    ran = []
    with _taking_turns("x"):
        ran.append(1)
    (lock,) = tmp_path.iterdir()
    assert lock.name.startswith(f"kinswarm-{os.getuid()}-"), lock.name
    monkeypatch.setattr(tempfile, "gettempdir", lambda: str(tmp_path / "missing"))
    with _taking_turns("x"):
        ran.append(2)
    assert ran == [1, 2]
