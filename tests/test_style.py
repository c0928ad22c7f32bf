"""The house style is checked, not hoped for: `ruff check` and `ruff format --check` over the repository's tracked
Python files (`git ls-files`), with the ruff version pinned in pyproject.toml (versions format differently). A user's
own script saved in the clone is theirs: it is not the repository's style to check."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def tracked_python_files(root: Path = ROOT) -> list[str]:
    """The repository's own `.py` files; the test is skipped outside a git checkout (an unpacked sdist)."""
    try:
        r = subprocess.run(
            ["git", "ls-files", "-z", "--", "*.py"], cwd=root, capture_output=True, text=True, timeout=60
        )
    except OSError as e:
        pytest.skip(f"git is not available ({e.strerror}): the tracked files are unknown")
    if r.returncode != 0:
        pytest.skip(f"{root} is not a git checkout: the tracked files are unknown")
    # a tracked file deleted in the work tree is not there to check
    return [f for f in r.stdout.split("\0") if f and (root / f).is_file()]


def ruff(args: list[str], root: Path) -> subprocess.CompletedProcess[str]:
    files = tracked_python_files(root)
    assert files, f"git ls-files found no Python file in {root}"
    cmd = [sys.executable, "-m", "ruff", *args, "--", *files]
    return subprocess.run(cmd, cwd=root, capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize("args", [["check"], ["format", "--check"]], ids=["lint", "format"])
def test_ruff_is_clean(args: list[str]) -> None:
    r = ruff(args, ROOT)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-1000:]


@pytest.mark.parametrize("args", [["check"], ["format", "--check"]], ids=["lint", "format"])
def test_a_users_own_script_in_the_clone_is_not_checked(tmp_path: Path, args: list[str]) -> None:
    """A clone with a user's untracked script that both checks refuse (an unused import, unformatted): the check of
    the tracked files passes; the same script tracked fails it (the check can fail)."""
    git = ["git", "-c", "user.name=t", "-c", "user.email=t@t", "-c", "init.defaultBranch=main"]
    subprocess.run([*git, "init", "-q"], cwd=tmp_path, check=True, timeout=60)
    (tmp_path / "mod.py").write_text('"""A tracked module."""\n\nX = 1\n')
    (tmp_path / "mine.py").write_text("import os\nx=1\n")
    subprocess.run([*git, "add", "mod.py"], cwd=tmp_path, check=True, timeout=60)
    assert tracked_python_files(tmp_path) == ["mod.py"]
    assert ruff(args, tmp_path).returncode == 0
    subprocess.run([*git, "add", "mine.py"], cwd=tmp_path, check=True, timeout=60)
    assert ruff(args, tmp_path).returncode == 1
