"""`python -m kinswarm.experiments.research NAME [--quick] [--seeds N] [--jobs N] [--out DIR]`."""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys
import time
from pathlib import Path

from kinswarm.experiments.common import Context

from . import __path__ as here


def main(argv: list[str] | None = None) -> int:
    names = sorted(m.name for m in pkgutil.iter_modules(here) if not m.name.startswith("_"))
    p = argparse.ArgumentParser(prog="python -m kinswarm.experiments.research", description=__doc__)
    p.add_argument("name", choices=names)
    p.add_argument("--quick", action="store_true", help="a smoke version (seconds, not conclusions)")
    p.add_argument("--seeds", type=int, default=None, help="seeds 0..N-1 (default: the study's own)")
    p.add_argument("--jobs", type=int, default=2, help="runs in parallel worker processes (default 2)")
    p.add_argument("--out", type=Path, default=Path("runs/research"))
    a = p.parse_args(argv)
    module = importlib.import_module(f"{__package__}.{a.name}")
    seeds = a.seeds or (1 if a.quick else module.SEEDS)
    ctx = Context(
        name=a.name,
        out=a.out / a.name,
        runs=a.out / "runs",
        seeds=seeds,
        quick=a.quick,
        jobs=a.jobs,
        argv=["python -m kinswarm.experiments.research", *(argv if argv is not None else sys.argv[1:])],
        started=time.perf_counter(),
    )
    module.run(ctx)
    print(ctx.out / "report.md" if (ctx.out / "report.md").exists() else ctx.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
