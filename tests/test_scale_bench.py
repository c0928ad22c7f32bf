"""benchmarks/scale.py at smoke size: chains and trees of 4 and 8 joints in `process` placement, one repeat, a few
steps. The table's columns and the JSON's keys are the benchmark's interface (docs/scale.md reads them); the numbers
must be what the run was: one process per actor, each with a Zenoh session, connections between them."""

from __future__ import annotations

import json
import os
import sys
import tempfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "benchmarks"))

import scale  # noqa: E402
from kinswarm.experiments.arms import depth, link_length, parents, run_file  # noqa: E402
from kinswarm.protocol.robots import load_robot  # noqa: E402


def test_run_files_keep_the_reach(tmp_path):
    """A chain's depth is N, a tree's grows as log N with at most 3 children a joint; the tip reaches 12 at every
    N (the tree's: its leaves' centroid, every link pointing one way), and the loader reads every file."""
    for n in (4, 8, 16, 32, 64):
        chain = load_robot(run_file("chain", n, tmp_path / f"chain{n}.toml"))
        tree = load_robot(run_file("tree", n, tmp_path / f"tree{n}.toml"))
        assert len(chain.dof_agents) == len(tree.dof_agents) == n
        assert chain.reach == pytest.approx(12.0) and depth("chain", n) == n
        assert max(len(a.children) for a in tree.agents.values()) <= 3
        d = depth("tree", n)  # filled breadth first: d levels hold up to (3^d - 1) / 2 joints
        assert (3 ** (d - 1) - 1) // 2 < n <= (3**d - 1) // 2
        par = parents("tree", n)
        leaves = [i for i in range(n) if i not in set(par[1:])]
        hops = []
        for i in leaves:
            d, j = 1, i
            while par[j] is not None:
                j, d = par[j], d + 1
            hops.append(d)
        assert sum(hops) / len(hops) * link_length("tree", n) == pytest.approx(12.0)


@pytest.mark.slow  # four process runs of the benchmark: minutes on 2 cores (`pytest -m slow`)
@pytest.mark.timeout(900)
def test_scale_bench_smoke(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))  # the runs' directories, and nothing left outside
    out = tmp_path / "scale.json"
    argv = ["--n", "4,8", "--topologies", "chain,tree", "--placements", "process", "--hosts-n", "", "--epochs", "2",
            "--steps", "100", "--json", str(out)]  # fmt: skip
    assert scale.main(argv) == 0
    printed = capsys.readouterr().out
    header = next(line for line in printed.splitlines() if line.startswith("| N |"))
    assert [c.strip() for c in header.strip("|").split("|")] == list(scale.COLUMNS)
    doc = json.loads(out.read_text())
    assert {"command", "columns", "machine", "epochs", "steps", "repeats", "load_end", "rows"} <= set(doc)
    rows = doc["rows"]
    assert sorted((r["n"], r["topology"]) for r in rows) == [(4, "chain"), (4, "tree"), (8, "chain"), (8, "tree")]
    for r in rows:
        assert set(r) == set(scale.ROW_KEYS)
        assert r["result"] == "ok", r["result"]  # no fixed start-up deadline: a loaded machine starts later, not never
        n = r["n"]
        # the supervisor, its hub and zygote, the sim and one process per agent; all but the zygote hold a Zenoh
        # session, and each client one connection to the hub (counted at both ends)
        assert r["processes"] == n + 4 and r["actors"] == n + 1 and r["sessions"] == n + 3
        assert r["tcp_total"] >= 2 * (n + 2) and r["tcp_per_process"] == pytest.approx(r["tcp_total"] / (n + 4), 0.05)
        assert 0 < r["first_step_s"] <= r["summary_s"] <= r["exit_s"]  # exit: ended once the summary is written
        assert r["steps_per_s"] > 0 and r["cpu_ms_per_step"] > 0 and r["cpu_total_s"] > 0
        assert r["agent_rss_mb"] > 10 and 0 < r["agent_pss_mb"] <= r["agent_rss_mb"] and r["sim_pss_mb"] > 0
        roles = sorted(p["role"] for p in r["per_process"])
        assert roles == sorted(["supervisor", "hub", "zygote", "sim", *["agent"] * n])
    # nothing of the runs outlives the benchmark
    left = []
    for pid in os.listdir("/proc"):
        try:
            if pid.isdigit() and str(tmp_path).encode() in Path(f"/proc/{pid}/cmdline").read_bytes():
                left.append(int(pid))
        except OSError:
            pass
    assert left == []


def test_bad_flags_are_one_line(capsys):
    with pytest.raises(SystemExit) as e:
        scale.main(["--topologies", "ring"])
    assert e.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert "unknown topology or placement 'ring'" in err[-1] and "Traceback" not in "\n".join(err)
