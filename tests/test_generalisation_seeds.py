"""The generalisation experiment's Level-3 rows on many seeds: which rows run on how many, how firm the report says
each is (standard error, range, worst seeds), the plain verdict against the rule, and the any-pose rows' untrained
and blind controls. No swarm runs: run_specs is replaced by outcomes whose errors are set per seed."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from kinswarm.actors.files.runfile import learner_settings, task_of
from kinswarm.actors.learning.fuzzy import memberships_1d
from kinswarm.experiments import generalisation
from kinswarm.experiments.common import Context
from kinswarm.experiments.generalisation import protocol
from kinswarm.experiments.generalisation.protocol import (
    ANY_POSE,
    BLIND_FREE,
    FREE_JOINTS,
    L3_SEEDS,
    any_pose,
    any_pose_controls,
    train_and_test,
    training_spec,
)
from kinswarm.experiments.generalisation.report import _against_the_rule, spread
from kinswarm.experiments.swarm import RunOutcome

SUCC = f"{ANY_POSE}, successive test goals"


def fake_runs(tmp_path: Path, ran: list) -> object:
    """run_specs without runs: each goal's error is 0.1 + 0.01 * seed for a swarm (seed 19 the worst), 0.15 for the
    rule, so every row's per-seed means are known."""

    def run_specs(ctx, specs, desc=""):
        ran.extend(specs)
        out = []
        for s in specs:
            e = 0.15 if s.controller != "agents" else 0.1 + 0.01 * s.seed
            out.append(RunOutcome(s, tmp_path / s.name, {}, [{"final_error": e, "errors": [e]}] * s.epochs))
        return out

    return run_specs


@pytest.fixture
def full_report(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> tuple[list, str, dict]:
    """`kinswarm experiment generalisation --seeds 3` (not --quick) with no swarm run: its specs, report and
    results."""
    ran: list = []
    monkeypatch.setattr(protocol, "run_specs", fake_runs(tmp_path, ran))
    ctx = Context("generalisation", tmp_path / "out", tmp_path / "runs", seeds=3, quick=False, test_set=0)
    generalisation.run(ctx)
    return ran, (ctx.out / "report.md").read_text(), json.loads((ctx.out / "results.json").read_text())


def test_every_level3_row_runs_on_L3_SEEDS_the_any_pose_controls_on_fewer(full_report) -> None:
    _, _, results = full_report
    assert L3_SEEDS >= 20
    levels = results["levels"]
    l3 = [
        "Level-3",
        "Level-3, successive test goals",
        "Level-3, successive test goals, joints free",
        ANY_POSE,
        SUCC,
    ]
    for label in l3:
        assert levels[label]["seeds"] == list(range(L3_SEEDS)), label
    kinds = {row["kind"]: row["seeds"] for row in levels.values() if row["kind"] in protocol.CONTROLS}
    assert kinds == {kind: list(range(L3_SEEDS)) for kind in protocol.CONTROLS}
    # the any-pose rows' controls on --seeds seeds; the other levels too
    assert levels[f"{ANY_POSE}, untrained, successive test goals"]["seeds"] == [0, 1, 2]
    assert levels["Level-2"]["seeds"] == [0, 1, 2]
    # the successive rows' test runs: one per seed on test sets 0 and 1
    per = results["per_level"]
    for label in l3:
        assert [len(per[label][f"test_set_{b}"]["per_seed"]) for b in (0, 1)] == [L3_SEEDS] * 2, label


def test_the_report_says_how_firm_each_row_on_many_seeds_is(full_report) -> None:
    _, report, results = full_report
    f = results["per_level"]["Level-3"]["test_set_0"]["over_seeds"]
    means = 0.1 + 0.01 * np.arange(L3_SEEDS)
    assert f["seeds"] == L3_SEEDS and f["mean"] == pytest.approx(means.mean())
    assert f["mean_se"] == pytest.approx(means.std(ddof=1) / math.sqrt(L3_SEEDS), abs=1e-6)  # results.json: 6 digits
    assert (f["mean_min"], f["mean_max"]) == (pytest.approx(0.1), pytest.approx(means[-1]))
    assert [w["seed"] for w in f["worst"]] == [19, 18, 17]
    line = f"- Level-3, test set 0 ({L3_SEEDS} seeds): mean {means.mean():.3f} ± {f['mean_se']:.3f} (SE; seeds "
    assert line in report and "worst seeds 19: 0.290 (100 %), 18: 0.280 (100 %)" in report
    assert f"- {SUCC}, test set 1 ({L3_SEEDS} seeds)" in report
    # rows on fewer than 10 seeds get no such line (their table row's ± is all they have)
    assert "over_seeds" not in results["per_level"]["Level-2"]["test_set_0"]
    assert "- Level-2, test set 0 (" not in report


def test_the_report_says_plainly_whether_the_any_pose_skill_beats_the_rule(full_report) -> None:
    _, report, _ = full_report
    for b in (0, 1):  # the rule's successive row on the free chain, on both sets beside the any-pose row
        assert f"successive test goals, joints free, trained from random poses, test set {b}: Level-3 frozen" in report
    # swarm mean 0.195 ± 0.013 against the rule's 0.15, every goal within 0.5 for both: the rule is better
    assert (
        "test set 0: Level-3 frozen 0.195 ± 0.013 SE (20 seeds, 100 % within 0.5), the rule 0.150 (100 %): " in report
    )
    assert "**the rule is better**" in report
    assert "- Summed up: the learned skill beats the rule plainly in **0 of 8** comparisons above" in report
    # how firm the paper verdict is: the paper's 0.2366 against Level-3's 0.195 ± 0.013 (SE over 20 seeds)
    assert "kinswarm 0.195 ± 0.059 over seeds (SE 0.013: the paper's mean 3.1 SE above; STD 0.000)" in report
    assert "- From the start configuration, test set 0: the any-pose recipe 0.195" in report
    assert (
        "Control, Level-3, random starts, joints free, untrained, successive test goals, test set 1 (3 seeds)" in report
    )
    assert "Control, Level-3, random starts, joints free, blind (q only), successive test goals, test set 0" in report


def _entry(means: list[float], within: list[float]) -> dict:
    per_seed = [{"mean": m, "frac_within_0_5": w} for m, w in zip(means, within, strict=True)]
    return {
        "per_seed": per_seed,
        "mean": float(np.mean(means)),
        "mean_std_over_seeds": float(np.std(means, ddof=1)),
        "frac_within_0_5": float(np.mean(within)),
    }


@pytest.mark.parametrize(
    ("means", "within", "rule", "verdict"),
    [
        ([0.10, 0.11, 0.12, 0.13], [0.95] * 4, (0.2, 0.94), "the trained swarm is **better**"),
        ([0.30, 0.31, 0.32, 0.33], [0.90] * 4, (0.2, 0.94), "**the rule is better**"),
        # a lower mean by more than 2 SE but fewer goals within 0.5: not plainly better
        (
            [0.10, 0.11, 0.12, 0.13],
            [0.92] * 4,
            (0.2, 0.94),
            "**neither beats the other plainly**: the swarm's mean lower",
        ),
        # the same mean within the noise over seeds
        (
            [0.10, 0.30, 0.12, 0.26],
            [0.95] * 4,
            (0.2, 0.94),
            "**neither beats the other plainly**: the swarm's mean lower",
        ),
    ],
)
def test_the_verdict_against_the_rule_needs_two_standard_errors_and_no_fewer_goals_reached(
    means: list[float], within: list[float], rule: tuple[float, float], verdict: str
) -> None:
    per = {SUCC: {"test_set_0": _entry(means, within)}}
    refs = {
        "rule on g_perp, successive test goals, joints free": {
            "test_set_0": {"mean": rule[0], "frac_within_0_5": rule[1]}
        }
    }
    line, summed = _against_the_rule(per, refs, 0)
    assert verdict in line, line
    who = {"the trained swarm is **better**": "**1 of 1**", "**the rule is better**": "**0 of 1**"}
    assert who.get(verdict, "**0 of 1**") in summed and ("swarm in 1;" in summed) == (
        verdict == "**the rule is better**"
    )


def test_spread_of_two_seeds() -> None:
    f = spread([{"mean": 0.2, "frac_within_0_5": 0.9}, {"mean": 0.4, "frac_within_0_5": 0.8}], [3, 7])
    assert f["mean_se"] == pytest.approx(0.1) and f["within_min"] == 0.8
    assert [(w["seed"], w["mean"]) for w in f["worst"]] == [(7, 0.4), (3, 0.2)]


def test_the_any_pose_controls_untrained_and_blind(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    ran: list = []
    monkeypatch.setattr(protocol, "run_specs", fake_runs(tmp_path, ran))
    ctx = Context("generalisation", tmp_path / "out", tmp_path / "runs", seeds=2, quick=False, test_set=0)
    tested = train_and_test(ctx, [*any_pose(), *any_pose_controls()], second_level=3, with_scratch=False)
    trains = [s for s in ran if s.learn and s.controller == "agents"]
    assert len(trains) == 4 and all(s.file == FREE_JOINTS and dict(s.task)["start_pose"] == "random" for s in trains)
    untrained = [s for s in ran if s.name.endswith("-untrained")]
    # frozen, never trained (no checkpoint to start from), the paper's way, on sets 0 and 1, on the free chain
    assert len(untrained) == 4 and all(
        s.from_dir is None and not s.learn and not s.explore and s.successive and s.file == FREE_JOINTS
        for s in untrained
    )
    assert {s.goals[0] for s in untrained} == {s.goals[0] for s in ran if s.successive and s.from_dir}
    blind_tests = [s for s in ran if s.from_dir and "blind" in s.from_dir]
    assert len(blind_tests) == 8 and {s.successive for s in blind_tests} == {False, True}
    assert set(tested.per[f"{ANY_POSE}, untrained, successive test goals"]) == {"test_set_0", "test_set_1"}
    assert f"{ANY_POSE}, untrained, successive test goals" not in tested.train_err
    # the blind swarm's state: its own angle in sets over the free chain's range, every other variable in sets so
    # wide that no value it meets tells them apart
    (blind,) = [t for t in any_pose_controls() if t.learner == BLIND_FREE and not t.successive]
    cfg = training_spec(blind, 0, 500).config(tmp_path)
    settings = learner_settings(task_of(cfg), cfg.learner)["a2"]
    spans = []
    for (lo, hi), m, x in zip(
        settings.state_ranges, settings.state_sets, (300.0, 3.0, 12.0, 24.0, 24.0, 3.0, 1.5), strict=True
    ):
        mu = [memberships_1d(v, m, lo, hi, settings.slope) for v in (-x, 0.0, x)]
        spans.append(max(float(np.abs(a - b).max()) for a in mu for b in mu))
    assert spans[0] > 0.5 and max(spans[1:]) < 0.05, spans
