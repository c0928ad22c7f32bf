"""A hung Hypothesis test is ended by its timeout, and the session goes on (tests/hypothesis_timeout.py). Without the
hook, pytest-timeout's failure is taken by Hypothesis for a failing example, run again to shrink it, and the test
hangs for good: this runs a hanging property in a pytest of its own, with a 2 s limit."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent

HANGING = """
import time
from hypothesis import given, settings, strategies as st

@settings(max_examples=50, deadline=None, database=None)
@given(st.integers())
def test_hangs(x):
    print("an example started", flush=True)
    time.sleep(3600)

def test_runs_after():
    pass
"""


def _pytest(tmp_path: Path, *plugin: str) -> subprocess.Popen:
    (tmp_path / "test_hang.py").write_text(HANGING)
    (tmp_path / "pytest.ini").write_text("[pytest]\n")  # not the project's settings
    argv = [sys.executable, "-m", "pytest", "test_hang.py", "-q", "-s", "-p", "no:cacheprovider", "--timeout", "2"]
    env = {"PYTHONPATH": str(TESTS), "PATH": "/usr/bin:/bin"}
    return subprocess.Popen([*argv, *plugin], cwd=tmp_path, env=env, stdout=subprocess.PIPE, text=True)


@pytest.mark.timeout(300)
def test_a_hung_property_ends_at_its_timeout(tmp_path):
    p = _pytest(tmp_path, "-p", "hypothesis_timeout")
    try:
        out, _ = p.communicate(timeout=240)  # a guard: it ends 2 s after the example starts
    finally:
        p.kill()
        p.wait()
    assert p.returncode == 1 and "1 failed, 1 passed" in out, out[-3000:]
    assert "TimedOut" in out and out.count("an example started") == 1, out[-3000:]


@pytest.mark.timeout(300)
def test_without_the_hook_the_hung_example_is_run_again(tmp_path):
    """Why the hook is there: pytest-timeout alone ends the first run of the example, and Hypothesis starts it again
    (which hangs with no timer left). Killed once the second run starts."""
    p = _pytest(tmp_path)
    started = 0
    try:
        for line in p.stdout:  # type: ignore[union-attr]
            started += "an example started" in line
            if started == 2:
                break
    finally:
        p.kill()
        p.wait()
    assert started == 2, "the hung example was not run again: the hook may no longer be needed"
