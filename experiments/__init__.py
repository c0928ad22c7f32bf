"""The paper's experiments, one command each: `kinswarm experiment NAME [--seeds N] [--quick] [--out DIR]`.

Each writes DIR/NAME/report.md (figures, a "paper | kinswarm" table, commands, seeds, wall time, settings)
and DIR/NAME/results.json. Runs live in DIR/runs/ and are shared: `all` trains each configuration once.
"""

from __future__ import annotations

import importlib
import time
from pathlib import Path
from typing import Any

# `all` runs them in this order: optimality's long default-s runs are reused by convergence (their first
# epochs) and robustness (the trained swarm).
EXPERIMENTS = ("cost", "optimality", "convergence", "robustness", "generalisation")
# Run by name only, not by `all` (their own reports, their own cost): the evidence for the learner the README
# recommends for generalisation, what learning buys under faults in the robot's model, the paper's corridor and
# grasp (§5.4, §5.5), reaching points and poses in 3D on a real arm, the moving goal, and the deep-RL peers
BY_NAME: tuple[str, ...] = ("ablations", "adapt", "corridor", "grasp", "reach3d", "pose3d", "track", "peers")


def run_experiment(
    name: str,
    *,
    seeds: int = 3,
    quick: bool = False,
    out: Path = Path("runs/experiments"),
    jobs: int = 1,
    test_set: int = 0,
    argv: list[str] | None = None,
) -> dict[str, Any]:
    """Run one experiment (or `all`); returns {name: results}. Reports land in out/NAME/."""
    if seeds < 1:
        raise ValueError(f"--seeds must be >= 1, got {seeds}")
    if test_set < 0:
        raise ValueError(f"--test-set must be >= 0, got {test_set}")
    names = EXPERIMENTS if name == "all" else (name,)
    unknown = [n for n in names if n not in EXPERIMENTS + BY_NAME]
    if unknown:
        raise ValueError(f"unknown experiment {unknown[0]!r}; choose from {', '.join(EXPERIMENTS + BY_NAME)} or all")
    from .common import Context  # here: the CLI imports the names above without the experiments' machinery

    out = Path(out)
    results: dict[str, Any] = {}
    for n in names:
        ctx = Context(
            name=n,
            out=out / n,
            runs=out / "runs",
            seeds=seeds,
            quick=quick,
            jobs=jobs,
            test_set=test_set,
            argv=list(argv) if argv else [],
            started=time.perf_counter(),
        )
        module = importlib.import_module(f"{__name__}.{n}")
        results[n] = module.run(ctx)
    return results
