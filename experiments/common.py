"""What every experiment shares: the context (seeds, size, output), running specs (in parallel worker
processes when --jobs > 1), statistics over seeds, and the report (report.md + results.json)."""

from __future__ import annotations

import json
import math
import os
import platform
import signal
import statistics
import sys
import threading
import time
from collections.abc import Iterable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from multiprocessing import get_context
from pathlib import Path
from typing import Any

from kinswarm.actors.learning.settings import LearnerSettings

from .swarm import RunOutcome, Spec, json_default, learner_overrides, run_spec

PLACEMENT_NOTE = (
    "Every swarm run uses `kinswarm run`'s machinery. A run that needs no messages (the learning agents of one "
    "robot, no process or link fault, no trace of the step messages) runs in the `inprocess` placement: the step "
    "library the actors call, as one plain loop, with the same errors, metrics and checkpoints for the same seed "
    "(tests/test_inprocess.py). The others (the model-based controllers, traced runs) run in `single` placement: the "
    "supervisor, agent and simulator actors exchanging the same messages over Zenoh, every actor an asyncio task in "
    "one process; `process` placement gives bit-identical errors for the same seed (tests/test_swarm.py)."
)
DEFAULTS = LearnerSettings()


@dataclass
class Context:
    name: str
    out: Path  # DIR/NAME
    runs: Path  # DIR/runs: shared by the experiments, so `all` reuses runs between them
    seeds: int
    quick: bool
    jobs: int = 1
    test_set: int = 0
    argv: list[str] = field(default_factory=list)
    started: float = field(default_factory=time.perf_counter)

    @property
    def seed_list(self) -> list[int]:
        return list(range(self.seeds))

    def command(self) -> str:
        if not self.argv:
            return f"kinswarm experiment {self.name}"
        research = self.argv[0].startswith("python ")  # research/__main__.py names its own program first
        return " ".join(self.argv) if research else "kinswarm " + " ".join(self.argv)

    def program(self) -> str:
        """What runs one report of this kind: `kinswarm experiment`, or the research modules' runner."""
        return self.argv[0] if self.argv and self.argv[0].startswith("python ") else "kinswarm experiment"


def settings(**kw: Any) -> tuple[tuple[str, Any], ...]:
    """LearnerSettings overrides, as given: a value equal to the dataclass's default is kept, since a task or state
    kind may build its learner on another (the turn state's lr). Equal runs share a cache entry however they are
    spelled (Spec.identity hashes the learners as built)."""
    return learner_overrides(**kw)


def _progress(total: int, desc: str) -> Any:
    if not sys.stderr.isatty():
        return None
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="run", dynamic_ncols=True)


_PARENT: int | None = None  # in a worker: the pid of the process that started it


def _orphaned() -> bool:
    return _PARENT is not None and os.getppid() != _PARENT


def _exit_with_parent(parent: int) -> None:
    """A worker's initializer: when its parent is gone (killed: Ctrl-C reaches the workers themselves) the
    worker interrupts its run as Ctrl-C would (the swarm closes its sessions and worlds; an unfinished run is
    never cached) and exits then, at the latest 30 s later, instead of running the batch on for nobody."""
    global _PARENT
    _PARENT = parent
    # started from a background job a worker inherits SIGINT ignored, and asyncio.run then leaves it so
    signal.signal(signal.SIGINT, signal.default_int_handler)

    def watch() -> None:
        while not _orphaned():
            time.sleep(0.5)
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(30.0)
        os._exit(1)

    threading.Thread(target=watch, name="exit-with-parent", daemon=True).start()


def worker_pool(jobs: int) -> ProcessPoolExecutor:
    """`jobs` spawned worker processes (spawn: a fork would copy any open Zenoh session) that end with their
    parent."""
    return ProcessPoolExecutor(
        max_workers=jobs, mp_context=get_context("spawn"), initializer=_exit_with_parent, initargs=(os.getpid(),)
    )


def _run_one(args: tuple[Spec, str]) -> RunOutcome:
    spec, runs = args
    try:
        if _orphaned():
            raise RuntimeError("the experiment that queued this run is gone")
        return run_spec(spec, Path(runs))
    finally:
        if _orphaned():  # the run has stopped and cleaned up: do not take the next one from the queue
            os._exit(1)


def run_specs(ctx: Context, specs: Sequence[Spec], desc: str = "") -> list[RunOutcome]:
    """Run (or reuse) every spec; in `ctx.jobs` spawned worker processes when > 1. Results in spec order."""
    ctx.runs.mkdir(parents=True, exist_ok=True)
    bar = _progress(len(specs), f"{ctx.name} {desc}".strip())
    out: list[RunOutcome] = []
    try:
        if ctx.jobs <= 1 or len(specs) <= 1:
            for s in specs:
                out.append(run_spec(s, ctx.runs))
                if bar is not None:
                    bar.update(1)
        else:
            # longest first, so one long run does not start last and hold up the batch
            order = sorted(range(len(specs)), key=lambda i: -specs[i].epochs * specs[i].steps)
            got: dict[int, RunOutcome] = {}
            with worker_pool(ctx.jobs) as pool:
                futures = {pool.submit(_run_one, (specs[i], str(ctx.runs))): i for i in order}
                for f in as_completed(futures):
                    got[futures[f]] = f.result()
                    if bar is not None:
                        bar.update(1)
            out = [got[i] for i in range(len(specs))]
    finally:
        if bar is not None:
            bar.close()
    return out


# -- statistics --------------------------------------------------------------------------------------
def mean_std(values: Iterable[float]) -> tuple[float, float]:
    """Mean and sample standard deviation (ddof = 1; 0 for a single value); NaNs are left out."""
    v = [float(x) for x in values if not math.isnan(float(x))]
    if not v:
        return math.nan, math.nan
    return statistics.fmean(v), statistics.stdev(v) if len(v) > 1 else 0.0


def pm(values: Iterable[float], digits: int = 3) -> str:
    m, s = mean_std(values)
    if math.isnan(m):
        return "—"
    return f"{m:.{digits}f} ± {s:.{digits}f}"


def frac_within(errors: Sequence[float], tol: float = 0.5) -> float:
    return sum(e <= tol for e in errors) / len(errors) if errors else math.nan


def settled_epoch(final_errors: Sequence[float], tol: float = 0.5, share: float = 0.8) -> float:
    """First epoch from which the final error is <= tol in that epoch and in >= `share` of the epochs after
    it (NaN if never): "the epoch by which the swarm has converged"."""
    n = len(final_errors)
    ok = [e <= tol for e in final_errors]
    for i in range(n):
        if ok[i] and sum(ok[i:]) >= share * (n - i):
            return float(i)
    return math.nan


# -- the report --------------------------------------------------------------------------------------
class Report:
    """report.md (title, settings, tables, figures, commands) and results.json, written together."""

    def __init__(self, ctx: Context, title: str, section: str) -> None:
        self.ctx, self.title, self.section = ctx, title, section
        self.parts: list[str] = []
        self.results: dict[str, Any] = {}
        ctx.out.mkdir(parents=True, exist_ok=True)

    def text(self, *lines: str) -> None:
        self.parts.append("\n".join(lines))

    def table(self, header: Sequence[str], rows: Iterable[Sequence[Any]]) -> None:
        lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
        lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
        self.parts.append("\n".join(lines))

    def figure(self, name: str, caption: str) -> None:
        self.parts.append(f"![{caption}]({name})\n\n*{caption}*")

    def save_figure(self, fig: Any, name: str, caption: str) -> None:
        """Write a matplotlib figure next to report.md, close it, and show it in the report."""
        import matplotlib.pyplot as plt

        fig.tight_layout()
        fig.savefig(self.ctx.out / name, dpi=100)
        plt.close(fig)
        self.figure(name, caption)

    def write(self, settings_used: dict[str, Any], runs: Sequence[RunOutcome] = ()) -> Path:
        ctx = self.ctx
        wall = time.perf_counter() - ctx.started
        run_wall = sum(float(r.summary.get("wall_seconds", 0.0)) for r in runs)
        head = [
            f"# {self.title}",
            "",
            f"Paper section: {self.section}. Generated by `{ctx.command()}`"
            + (" (**quick** smoke version: too small for conclusions)." if ctx.quick else "."),
            "",
            f"- seeds: {ctx.seed_list} (tables: mean ± std over seeds, sample std)",
            f"- wall time of this command: {wall:.0f} s ({ctx.jobs} worker process(es)); the {len(runs)} swarm "
            f"runs it used took {run_wall:.0f} s of run time (runs reused from a shared cache count too)",
            f"- machine: {os.cpu_count()} cores, Python {platform.python_version()}, {platform.machine()}",
            f"- placement: {PLACEMENT_NOTE}{_in_processes(runs)}",
            f"- runs: `{_rel(ctx.runs)}/` (each with config.json, metrics.jsonl, summary.json, spec.json); "
            f"`{ctx.program()} {ctx.name} --seeds {ctx.seeds}{' --quick' if ctx.quick else ''} --out "
            f"{_rel(ctx.out.parent)}` redoes only this experiment, reusing every finished run there",
        ]
        body = "\n\n".join(["\n".join(head), *self.parts])
        body += "\n\n## Settings\n\n```json\n" + json.dumps(settings_used, indent=1, default=json_default) + "\n```\n"
        (ctx.out / "report.md").write_text(body)
        res = {
            "experiment": ctx.name,
            "command": ctx.command(),
            "quick": ctx.quick,
            "seeds": ctx.seed_list,
            "wall_seconds": round(wall, 1),
            "run_seconds": round(run_wall, 1),
            "placement": _placements(runs),
            "settings": settings_used,
            **self.results,
        }
        (ctx.out / "results.json").write_text(json.dumps(_clean(res), indent=1, default=json_default) + "\n")
        return ctx.out / "report.md"


def _placements(runs: Sequence[RunOutcome]) -> str | dict[str, int]:
    """The one placement every run went in, or how many runs went in each."""
    counts: dict[str, int] = {}
    for r in runs:
        counts[r.placement] = counts.get(r.placement, 0) + 1
    return next(iter(counts)) if len(counts) == 1 else counts


def _in_processes(runs: Sequence[RunOutcome]) -> str:
    """Where this report's runs went (a run cached from a sitting before `inprocess` went in `single`)."""
    counts = _placements(runs)
    said = f" Here every run in `{counts}`." if isinstance(counts, str) else ""
    if isinstance(counts, dict):
        said = " Here: " + ", ".join(f"{n} run(s) in `{p}`" for p, n in sorted(counts.items())) + "."
    names = sorted({r.spec.name for r in runs if r.spec.placement == "process"})
    if names:
        said += f" In `process` placement (one OS process per actor, for process faults): {', '.join(names)}."
    return said if runs else ""


def _rel(p: Path) -> str:
    try:
        return str(p.resolve().relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(p)


def _clean(x: Any) -> Any:
    """JSON without NaN (null instead) and with plain floats."""
    if isinstance(x, dict):
        return {str(k): _clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_clean(v) for v in x]
    if isinstance(x, float):
        return None if math.isnan(x) or math.isinf(x) else round(x, 6)
    if hasattr(x, "item") and callable(x.item):  # numpy scalars
        return _clean(x.item())
    return x


def plt_module() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def band(ax: Any, curves: Sequence[Sequence[float]], label: str, color: str | None = None, ls: str = "-") -> None:
    """Mean over seeds, with a band from the lowest to the highest seed (a ±std band means little on the log
    axes these errors need)."""
    import numpy as np

    n = min(len(c) for c in curves)
    a = np.array([list(c)[:n] for c in curves], dtype=float)
    x = np.arange(n)
    (line,) = ax.plot(x, a.mean(axis=0), label=label, color=color, lw=1.4, ls=ls)
    ax.fill_between(x, a.min(axis=0), a.max(axis=0), color=line.get_color(), alpha=0.15, lw=0)
