"""docs/env.md runs as written: every code block of the page, in its order, as a reader would run them from a clone
(the python blocks in one interpreter, each seeing what the blocks before it made; the bash blocks in bash, with the
venv's `kinswarm`), in a directory of its own that sees the repository's examples/ and docs/. The blocks that need
SB3 (and so torch, which the test install does not pull: docs/env.md) run where it is installed; the others always."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "env.md"
NEEDS_SB3 = ("torch", "sb3", "stable_baselines3", "iiwa-shared")  # SB3's blocks, and what they made
VECTOR = "from kinswarm.env.sb3 import JointsVecEnv"

DRIVER = """
import json, subprocess, sys, time
blocks = json.load(open(sys.argv[1]))
ns = {"__name__": "__main__"}
for i, (lang, code) in enumerate(blocks):
    t0 = time.perf_counter()
    if lang == "python":
        exec(compile(code, f"docs/env.md block {i}", "exec"), ns)
    else:
        subprocess.run(["bash", "-euo", "pipefail", "-c", code], check=True)
    print(f"-- block {i} ({lang}): {time.perf_counter() - t0:.1f} s", flush=True)
print("ran", len(blocks), "blocks")
"""


def blocks() -> list[tuple[str, str]]:
    found = re.findall(r"^```(\w*)\n(.*?)^```", PAGE.read_text(), flags=re.M | re.S)
    assert found, "no code blocks found in docs/env.md"
    assert {lang for lang, _ in found} <= {"python", "bash"}, [lang for lang, _ in found]
    return found


def needs_sb3(code: str) -> bool:
    return any(word in code for word in NEEDS_SB3)


def run_blocks(tmp_path: Path, chosen: list[tuple[str, str]]) -> str:
    import json

    for name in ("examples", "docs"):
        (tmp_path / name).symlink_to(ROOT / name)
    (tmp_path / "blocks.json").write_text(json.dumps(chosen))
    (tmp_path / "driver.py").write_text(DRIVER)
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}"}
    env["MPLBACKEND"] = "Agg"  # the human render mode, if a block used it, draws without a display
    done = subprocess.run(
        [sys.executable, "driver.py", "blocks.json"], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=900
    )
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    assert f"ran {len(chosen)} blocks" in done.stdout
    return done.stdout + done.stderr


def test_the_pages_blocks_that_need_no_sb3_run_as_written(tmp_path: Path) -> None:
    chosen = [b for b in blocks() if not needs_sb3(b[1])]
    assert any("docs/results/peers/ppo-shared.toml" in code for _, code in chosen)  # the shipped policy, as a swarm
    out = run_blocks(tmp_path, chosen)
    assert "final error" in out or "within 0.5" in out  # the swarm's run said how it ended
    assert (tmp_path / "runs" / "ppo-shared" / "run.toml").is_file()


@pytest.mark.timeout(900)  # a hang guard: torch's import, three trainings, an export and a swarm on a loaded machine
def test_the_pages_sb3_blocks_run_as_written_and_the_vector_route_on_chain4_too(tmp_path: Path) -> None:
    pytest.importorskip("sb3_contrib", reason="sb3-contrib (and torch) are not in the test install: docs/env.md")
    chosen = [b for b in blocks() if needs_sb3(b[1])]
    (vector,) = [code for _, code in chosen if VECTOR in code]
    assert 'RUN_FILE = "examples/iiwa.toml"' in vector
    chosen.append(("python", vector.replace('RUN_FILE = "examples/iiwa.toml"', 'RUN_FILE = "examples/chain4.toml"')))
    out = run_blocks(tmp_path, chosen)
    assert "final error" in out
    assert (tmp_path / "iiwa-shared.onnx").is_file() and (tmp_path / "runs" / "iiwa-shared" / "run.toml").is_file()
    assert "7 joints x 2 copies" in out and "4 joints x 2 copies" in out
