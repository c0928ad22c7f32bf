"""`kinswarm fault` and `kinswarm status` are asked of a live run, often on a loaded machine, where a command's time is
mostly Python's start-up: they take a lean path (actors/cli/entry.py -> control.main) that imports neither numpy nor
the learners, the report or the launcher. The time itself is benchmarks/control_latency.py's; here, what is imported."""

from __future__ import annotations

import subprocess
import sys

import pytest

HEAVY = ("numpy", "kinswarm.actors.cli.commands", "kinswarm.actors.learning", "kinswarm.actors.report", "pybullet")
PROBE = """
import sys
sys.argv = ["kinswarm", *sys.argv[1:]]
from kinswarm.actors.cli.entry import main
try:
    code = main()
except SystemExit as e:
    code = e.code
heavy = [m for m in {heavy!r} if m in sys.modules or any(k.startswith(m + ".") for k in sys.modules)]
print("EXIT", code, "HEAVY", ",".join(heavy) or "-")
"""


@pytest.mark.parametrize(
    "argv",
    [
        ["fault", "r", "lock", "a2", "--run-dir", "{tmp}/r"],
        ["status", "r", "--run-dir", "{tmp}/r"],
        ["fault", "r", "freeze", "a2", "--for", "-5s"],
    ],
)
def test_fault_and_status_import_nothing_heavy_and_still_say_what_is_wrong(tmp_path, argv):
    args = [a.format(tmp=tmp_path) for a in argv]
    r = subprocess.run(
        [sys.executable, "-c", PROBE.format(heavy=HEAVY), *args], capture_output=True, text=True, timeout=300
    )
    assert r.stdout.strip().endswith("HEAVY -"), r.stdout + r.stderr
    assert "EXIT 2" in r.stdout, r.stdout  # a missing run, a bad duration: one line and exit code 2, as ever
    (line,) = r.stderr.strip().splitlines()
    assert line.startswith("kinswarm: error: ") and "Traceback" not in r.stderr, r.stderr


def test_the_whole_cli_offers_the_same_fault_and_status(capsys):
    from kinswarm.actors.cli.parser import build_parser

    a = build_parser().parse_args(["fault", "r", "freeze", "a2", "--for", "5s", "--run-dir", "d"])
    assert (a.command, a.fault, a.targets, a.duration, str(a.run_dir)) == ("fault", "freeze", ["a2"], "5s", "d")
    a = build_parser().parse_args(["status", "r", "--watch"])
    assert (a.command, a.run_id, a.watch) == ("status", "r", True)
