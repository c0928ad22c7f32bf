"""Nothing learned changed: small runs of the example run files give exactly the final and mean errors that the same
runs gave before the run-file redesign (tests/data/golden_runs.json records them, with the command lines of that
version). Each case here is today's command for the same run: the examples, the corridor's recommended recipe in
its two stages and its frozen replays (with and without the shield), the generalisation learner, baselines, a
scenario, in both placements where they apply."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from conftest import ROOT, free_port
from kinswarm.actors.cli.commands import main

GOLDEN = json.loads((ROOT / "tests" / "data" / "golden_runs.json").read_text())["runs"]
SMALL = ["--steps", "100", "--no-progress", "--deadline-ms", "10000"]
KINSWARM = [  # the corridor experiment's `kinswarm` configuration
    "task.clearance_state=true",
    "task.collision_state=true",
    "task.collision_penalty=-5",
    "learner.s=0.01",
    "learner.epsilon_decay=0.03",
    "learner.ranges=[[-3.1416,3.1416],[-3.1416,3.1416],[0,7],[-7,7],[-7,7],[-3.1416,3.1416]]",
]
# golden name -> today's command line for the same run ({stage1} and {stage2}: the recipe's run directories)
CASES: dict[str, list[str]] = {
    "chain4-single": ["run", "examples/chain4.toml", "--epochs", "3", "--placement", "single"],
    "chain4-process": ["run", "examples/chain4.toml", "--epochs", "3", "--placement", "process"],
    "tree5-single": ["run", "examples/tree5.toml", "--epochs", "3", "--placement", "single"],
    "tree5-process": ["run", "examples/tree5.toml", "--epochs", "3", "--placement", "process"],
    "corridor7-single": ["run", "examples/corridor7.toml", "--epochs", "3", "--placement", "single"],
    "corridor7-process": ["run", "examples/corridor7.toml", "--epochs", "3", "--placement", "process"],
    "grasp3-single": ["run", "examples/grasp3.toml", "--epochs", "2", "--placement", "single"],
    "grasp3-process": ["run", "examples/grasp3.toml", "--epochs", "2", "--placement", "process"],
    "chain4-strict-seed1": ["run", "examples/chain4.toml", "--epochs", "3", "--reward", "strict", "--seed", "1"],
    "chain4-paper-seed2": ["run", "examples/chain4.toml", "--epochs", "3", "--reward", "paper", "--seed", "2"],
    "chain4-goal-successive": ["run", "examples/chain4.toml", "--epochs", "3", "--goal=-5,7", "--successive"],
    "chain4-waypoints": ["run", "examples/chain4.toml", "--epochs", "3"]
    + ["--set", "task.waypoints=[[8.0, 4.0]]", "--set", "task.waypoint_radius=0.5"],
    "chain4-locked": ["run", "examples/chain4.toml", "--epochs", "2", "--scenario", "scenarios/paper-locked.toml"],
    "chain4-generalise": ["run", "examples/reach-generalise.toml", "--epochs", "3"],
    "corridor7-kinswarm": ["run", "examples/corridor7.toml", "--epochs", "3"]
    + [x for s in KINSWARM for x in ("--set", s)],
    "corridor7-paper": ["run", "examples/corridor7.toml", "--epochs", "2", "--reward", "paper"],
    "grasp3-paper": ["run", "examples/grasp3.toml", "--epochs", "2", "--reward", "paper"],
    "corridor-stage1-process": ["run", "examples/corridor7-inner200.toml", "--epochs", "4", "--placement", "process"],
    "baseline-pinv": ["baseline", "examples/chain4.toml", "--epochs", "1"],
    "baseline-greedy": ["baseline", "examples/chain4.toml", "--epochs", "1", "--law", "greedy"],
}
RECIPE: dict[str, list[str]] = {  # in order: each stage continues the one before
    "corridor-stage1-single": ["run", "examples/corridor7-inner200.toml", "--epochs", "4", "--out", "{stage1}"],
    "corridor-stage2": ["run", "examples/corridor7-freeze260.toml", "--epochs", "3", "--from", "{stage1}"]
    + ["--out", "{stage2}", "--set", "learner.lr_anneal=[4, 6]", "--set", "learner.count_freeze=4"],
    "corridor-frozen": ["run", "examples/corridor7-freeze260.toml", "--epochs", "1", "--from", "{stage2}"]
    + ["--learn", "off", "--explore", "off"],
    "corridor-frozen-shield": ["run", "examples/corridor7-freeze260.toml", "--epochs", "1", "--from", "{stage2}"]
    + ["--learn", "off", "--explore", "off", "--set", "scene.shield=0.02"],
}


def _run(args: list[str], out: Path) -> dict:
    args = list(args)
    if "--placement" not in args:
        args += ["--placement", "single"]
    if "--out" not in args:
        args += ["--out", str(out)]
    run_dir = Path(args[args.index("--out") + 1])
    listen = f"tcp/127.0.0.1:{free_port()}"
    assert main([*args, *SMALL, "--listen", listen, "--run-id", run_dir.name]) == 0
    return json.loads((run_dir / "summary.json").read_text())


def _check(name: str, summary: dict) -> None:
    want = GOLDEN[name]
    assert summary["final_error"] == want["final_error"], name
    assert summary["mean_error"] == want["mean_error"], name


def test_every_golden_run_has_a_case() -> None:
    assert set(GOLDEN) == set(CASES) | set(RECIPE)


@pytest.mark.parametrize("name", [n for n in CASES if not n.endswith("-process")])
def test_single_placement_runs_are_unchanged(name: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(ROOT)
    _check(name, _run(CASES[name], tmp_path / name))


@pytest.mark.timeout(300)
@pytest.mark.parametrize("name", [n for n in CASES if n.endswith("-process")])
def test_process_placement_runs_are_unchanged(name: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(ROOT)
    _check(name, _run(CASES[name], tmp_path / name))


def test_the_corridor_recipe_reproduces_its_flags(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The recommended corridor recipe, once two commands with 11 --learner flags each, as two run files."""
    monkeypatch.chdir(ROOT)
    dirs = {"stage1": str(tmp_path / "stage1"), "stage2": str(tmp_path / "stage2")}
    for name, args in RECIPE.items():
        _check(name, _run([a.format(**dirs) for a in args], tmp_path / name))
