"""The `inprocess` placement: the run file as one plain loop over the step library gives what the swarm gives — the
golden runs' errors to the last bit, the same metrics and records for the other examples — and what it cannot run
(process and link faults, fleets, the model-based laws) is refused in one line before anything starts."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from conftest import ROOT, free_port
from kinswarm.actors.cli.commands import main
from test_golden import CASES, GOLDEN, RECIPE, SMALL

LEARNING = [n for n in CASES if not n.endswith("-process") and not n.startswith("baseline")]


def _run(args: list[str], out: Path, placement: str = "inprocess") -> dict:
    args = [a for i, a in enumerate(args) if a != "--placement" and (i == 0 or args[i - 1] != "--placement")]
    if "--out" not in args:
        args += ["--out", str(out)]
    run_dir = Path(args[args.index("--out") + 1])
    extra = ["--listen", f"tcp/127.0.0.1:{free_port()}"] if placement != "inprocess" else []
    assert main([*args, *SMALL, *extra, "--placement", placement, "--run-id", run_dir.name]) == 0
    return json.loads((run_dir / "summary.json").read_text())


@pytest.mark.parametrize("name", LEARNING)
def test_the_golden_runs_come_out_the_same_in_process(name: str, tmp_path: Path, monkeypatch) -> None:
    monkeypatch.chdir(ROOT)
    s = _run(CASES[name], tmp_path / name)
    assert s["placement"] == "inprocess"
    assert (s["final_error"], s["mean_error"]) == (GOLDEN[name]["final_error"], GOLDEN[name]["mean_error"]), name


def test_the_corridor_recipe_comes_out_the_same_in_process(tmp_path: Path, monkeypatch) -> None:
    """Two stages, each from the one before (`--from`), then frozen replays: checkpoints written and read in process."""
    monkeypatch.chdir(ROOT)
    dirs = {"stage1": str(tmp_path / "stage1"), "stage2": str(tmp_path / "stage2")}
    for name, args in RECIPE.items():
        s = _run([a.format(**dirs) for a in args], tmp_path / name)
        assert (s["final_error"], s["mean_error"]) == (GOLDEN[name]["final_error"], GOLDEN[name]["mean_error"]), name


def _rows(run: Path, name: str) -> list[dict]:
    timing = ("seconds", "max_step_seconds", "t", "wall")
    lines = (run / name).read_text().splitlines()
    return [{k: v for k, v in json.loads(line).items() if k not in timing} for line in lines]


@pytest.mark.parametrize("example", ["chain4-track", "iiwa"])
def test_the_same_records_as_the_single_placement(example: str, tmp_path: Path, monkeypatch) -> None:
    """Beyond the golden runs: a moving goal and a robot from URDF, with the agents' traces recorded. The same metrics,
    poses, events and agent traces as a swarm of actors, and the same files but the actors' logs and keys."""
    monkeypatch.chdir(ROOT)
    args = ["run", f"examples/{example}.toml", "--epochs", "2", "--set", "run.record_agents=true"]
    if example == "chain4-track":  # joint faults from a scenario, as the simulator actor applies them
        scenario = tmp_path / "faults.toml"
        scenario.write_text(
            'name = "lock, reverse, free"\n\n[[event]]\nstep = 20\nepoch = 0\nfault = "lock"\ntarget = "a2"\n\n'
            '[[event]]\nstep = 50\nfault = "reverse"\ntarget = "a1"\n\n[[event]]\nstep = 70\nepoch = 1\n'
            'fault = "free"\ntarget = "all"\n'
        )
        args += ["--scenario", str(scenario)]
    runs = {p: tmp_path / p for p in ("single", "inprocess")}
    for placement, out in runs.items():
        _run(args, out, placement)
    for name in ("metrics.jsonl", "poses.jsonl", "events.jsonl"):
        assert _rows(runs["single"], name) == _rows(runs["inprocess"], name), name
    key = lambda r: (r["epoch"], r["agent"])  # noqa: E731
    by_agent = {p: sorted(_rows(out, "agents.jsonl"), key=key) for p, out in runs.items()}
    assert by_agent["single"] == by_agent["inprocess"]  # the actors' traces arrive in any order
    files = {p: {f.name for f in out.iterdir()} - {"logs", "net"} for p, out in runs.items()}
    assert files["single"] == files["inprocess"]
    assert {f.name for f in (runs["inprocess"] / "agents").iterdir()} == {
        f.name for f in (runs["single"] / "agents").iterdir()
    }


@pytest.mark.parametrize(
    "extra, says",
    [
        (["--set", "run.fleet=2"], "placement: inprocess runs one robot"),
        (["--scenario", "{kill}"], "event[0].fault: kill: needs --placement process or single"),
        (["--scenario", "{drop}"], "event[0].fault: drop: needs --placement process or single"),
    ],
)
def test_what_needs_processes_or_messages_is_refused_up_front(extra, says, tmp_path, monkeypatch, capsys) -> None:
    monkeypatch.chdir(ROOT)
    scenarios = {}
    for fault, more in (("kill", ""), ("drop", "rate = 0.1\nseconds = 1.0\n")):
        path = tmp_path / f"{fault}.toml"
        path.write_text(f'name = "{fault}"\n\n[[event]]\nstep = 5\nfault = "{fault}"\ntarget = "a2"\n{more}')
        scenarios[fault] = str(path)
    extra = [e.format(**scenarios) for e in extra]
    out = tmp_path / "r"
    code = main(["run", "examples/chain4.toml", "--placement", "inprocess", "--out", str(out), *extra, *SMALL])
    err = capsys.readouterr().err.strip().splitlines()
    assert code != 0 and len(err) == 1 and says in err[0], err
    assert not (out / "metrics.jsonl").exists()


def test_a_baseline_law_is_refused_in_process(tmp_path, monkeypatch, capsys) -> None:
    monkeypatch.chdir(ROOT)
    code = main(["baseline", "examples/chain4.toml", "--placement", "inprocess", "--out", str(tmp_path / "b"), *SMALL])
    err = capsys.readouterr().err.strip().splitlines()
    assert code != 0 and len(err) == 1 and "the pinv law runs in the process placement" in err[0], err


@pytest.mark.parametrize("kind", ["independent", "tabular"])
def test_the_learner_kinds_come_out_the_same_in_process(kind: str, tmp_path: Path, monkeypatch) -> None:
    """The controls run in every placement alike: the same final errors as single, checkpoints of their kind."""
    from kinswarm.actors.files.checkpoint import load_checkpoint

    monkeypatch.chdir(ROOT)
    args = ["run", "examples/chain4.toml", "--epochs", "2", "--set", f"learner.kind={kind}"]
    runs = {p: _run(args, tmp_path / p, p) for p in ("single", "inprocess")}
    assert runs["single"]["final_error"] == runs["inprocess"]["final_error"]
    _, meta = load_checkpoint(tmp_path / "inprocess" / "agents" / "a2.npz", agent="a2", learner=kind)
    assert meta["learner"] == kind
