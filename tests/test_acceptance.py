"""The spine's acceptance check (slow: `pytest -m slow`): 60 epochs over three seeds on the paper's
chain, and the same on other reachable goals and start angles. In `single` placement for speed; the
placement test shows `process` gives the same numbers."""

from __future__ import annotations

import statistics
from pathlib import Path

import pytest
import tomli_w
from conftest import EXAMPLES, free_port
from kinswarm.actors.cli.commands import _resolve, build_parser
from kinswarm.actors.run.launch import run_swarm

pytestmark = [pytest.mark.slow, pytest.mark.timeout(1800)]


def last20(topology: Path, tmp: Path, seed: int, extra: list[str]) -> list[float]:
    a = build_parser().parse_args(
        [
            "run",
            str(topology),
            "--placement",
            "single",
            "--epochs",
            "60",
            "--seed",
            str(seed),
            "--out",
            str(tmp),
            "--listen",
            f"tcp/127.0.0.1:{free_port()}",
            *extra,
        ]
    )
    cfg, topo = _resolve(a, "agents")
    return run_swarm(cfg, topo)["final_error"][-20:]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_chain4_learns_to_reach(tmp_path, chain4, seed):
    errs = last20(chain4, tmp_path, seed, [])
    assert sum(e <= 0.5 for e in errs) >= 16, errs
    assert statistics.median(errs) <= 0.15, errs


def chain4_from(start_deg: tuple[float, ...], path: Path) -> Path:
    """The example chain with other start angles: examples/chain4.toml as its `base`, its agents replaced (a list
    replaces a list)."""
    agents = [
        {"id": f"a{i + 1}", **({"parent": f"a{i}"} if i else {}), "initial_deg": float(q)}
        for i, q in enumerate(start_deg)
    ]
    path.write_text(tomli_w.dumps({"base": str(EXAMPLES / "chain4.toml"), "robot": {"agent": agents}}))
    return path


@pytest.mark.parametrize(
    "goal, start",
    [("-5,7", (0, 10, 20, 30)), ("8,-3", (0, 10, 20, 30)), ("4.16,6.18", (30, -20, 10, 0)), ("-3,-6", (90, 0, 0, 0))],
)
def test_other_goals_and_starts(tmp_path, goal, start):
    topo = chain4_from(start, tmp_path / "start.toml")
    errs = last20(topo, tmp_path / "run", 0, [f"--goal={goal}"])
    assert sum(e <= 0.5 for e in errs) >= 16, errs
    assert statistics.median(errs) <= 0.15, errs
