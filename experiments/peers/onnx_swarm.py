"""The ONNX-in-the-swarm row: a per-joint policy exported to ONNX, run as `kinswarm run` runs it, as a
`process`-placement swarm (one OS process per actor, over Zenoh) on unseen goals, intact and with a2 locked live while
it runs (the fault `kinswarm fault RUN-DIR lock a2` sends, through the same client), beside the same file stepped in
parallel_env (intact, and with a2 locked from each episode's first step).

The lab stands on the product, never on its command line: the command line reaches this module by the experiments'
table of names (`kinswarm experiment peers`), so running `kinswarm` from here would close a loop (tests/test_cycles.py).
What `kinswarm run FILE --out OUT` does with a run file is the product's one loader and `run_swarm`
(actors/files/runfile.py, actors/run/launch.py); the run's own process runs those, as this module's `__main__`, and
the fault goes through the command's client (actors/control/client.py).

Needs onnxruntime (the `onnx` extra), not torch: any ONNX file meeting the contract of docs/env.md will do.

Why the live lock compares to the env's lock from step 0: a lock lands at some step of some epoch (the sim's clock
says which, events.jsonl), and a fault stays across epochs while the world reset puts every joint at its initial
angle; so every epoch after the landing one is the env's episode with a2 locked from its first step.
"""

from __future__ import annotations

import asyncio
import json
import subprocess
import sys
import time
import tomllib
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from kinswarm.actors.learning.settings import OBSERVATION_FIELDS
from kinswarm.env import parallel_env

if TYPE_CHECKING:
    from kinswarm.actors.files.config import RunConfig
    from kinswarm.protocol.messages import Fault, FaultReply

ROOT = Path(__file__).resolve().parents[2]
RECIPE = ROOT / "examples" / "reach-generalise.toml"  # the observation and reward the peers were trained on
LOCK = [{"fault": "lock", "targets": ["a2"]}]
DEADLINE_MS = 10_000  # a loaded machine must not make a joint hold a step: the run stays a function of its inputs
Goal = tuple[float, float]


def _toml(v: Any) -> str:
    """One TOML value (strings, numbers, booleans, arrays and inline tables: what a run file holds)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return json.dumps(v)  # a TOML basic string escapes as JSON does
    if isinstance(v, int | float):
        return repr(float(v)) if isinstance(v, float) else str(v)
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{k} = {_toml(x)}" for k, x in v.items()) + " }"
    return "[" + ", ".join(_toml(x) for x in v) + "]"


def write_run_file(path: Path, policy: Path, goals: Sequence[Goal], steps: int, recipe: Path = RECIPE) -> Path:
    """A run file acting with `policy` (kind onnx) on `goals` (one epoch each, from the start pose) with the recipe's
    robot, task and observation: the recipe's learner table keeps only what S_i is made of (its other fields are the
    fuzzy learner's, refused with kind onnx)."""
    spec = tomllib.loads(recipe.read_text())
    base = (recipe.parent / spec["base"]).resolve() if "base" in spec else None
    learner = {k: v for k, v in spec.get("learner", {}).items() if k in OBSERVATION_FIELDS}
    task = {**spec.get("task", {}), "goals": [list(g) for g in goals]}
    run = {
        "placement": "process",
        "epochs": len(goals),
        "steps": steps,
        "seed": 0,
        "deadline_ms": DEADLINE_MS,
        "record": False,
        "checkpoint_every": 0,
    }
    tables = {"run": run, "task": task, "learner": {"kind": "onnx", "policy": str(policy.resolve()), **learner}}
    lines = [f"base = {_toml(str(base))}"] if base is not None else []
    for name, table in tables.items():
        lines += ["", f"[{name}]", *(f"{k} = {_toml(v)}" for k, v in table.items())]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")
    return path


def env_finals(run_file: Path, faults: list[dict[str, Any]] | None = None) -> list[float]:
    """The policy of `run_file` stepped in parallel_env, one episode per epoch of the file (its goals in order), as any
    user of the env takes the actions: the argmax of the scores over the moves the action mask allows. `faults`: from
    every episode's first step."""
    env = parallel_env(str(run_file), render_mode=None)
    try:
        learners = env.stepper.learners()  # the swarm's own builder: the OnnxPolicy objects the agents run
        finals = []
        for _ in range(env.stepper.cfg.epochs):
            obs, infos = env.reset(options={"faults": faults} if faults else None)
            while env.agents:
                actions = {}
                for a in env.possible_agents:
                    scores = learners[a].scores(obs[a]["observation"])
                    actions[a] = int(np.argmax(np.where(obs[a]["action_mask"] == 1, scores, -np.inf)))
                obs, _, _, _, infos = env.step(actions)
            finals.append(float(next(iter(infos.values()))["error"]))
        return finals
    finally:
        env.close()


def _run_command(run_file: Path, out: Path) -> list[str]:
    """The command line of a run's own process: this module run by name (`main`), as `kinswarm run RUN_FILE --out
    OUT` would run it."""
    return [sys.executable, "-m", "kinswarm.experiments.peers.onnx_swarm", str(run_file), str(out)]


def main(argv: list[str] | None = None) -> int:
    """`python -m kinswarm.experiments.peers.onnx_swarm RUN_FILE OUT`: the run of RUN_FILE into OUT, as `kinswarm run
    RUN_FILE --out OUT` makes it (the one loader, then run_swarm; its logging and thread switch interval; no progress
    bar: its output is a log); exit 1 if it failed or was interrupted."""
    from kinswarm.actors.files.runfile import load_run
    from kinswarm.actors.run.launch import run_swarm
    from kinswarm.actors.runtime import setup_logging

    run_file, out = (sys.argv[1:] if argv is None else argv)[:2]
    setup_logging("WARNING")
    sys.setswitchinterval(0.0005)  # as the command line sets it: Zenoh's callbacks get the GIL promptly
    cfg = load_run(Path(run_file), out=Path(out))
    summary = run_swarm(cfg, cfg.topo())
    if summary.get("error") or summary.get("interrupted"):
        print(f"kinswarm: the run failed: {summary.get('error') or 'interrupted'}", file=sys.stderr)
        return 1
    return 0


def _fault(run_dir: Path, kind: str, *targets: str) -> dict[str, Any]:
    """`kinswarm fault RUN-DIR KIND TARGETS...` as the command sends it, through its client (actors/control/client.py),
    in this process: its imports already paid for (a new interpreter would cost seconds of a loaded machine, and a
    short run may end before the fault is sent)."""
    from kinswarm.actors.control.client import Client, ControlError, make_fault, run_config_at, tool_net
    from kinswarm.protocol.faults import describe

    async def send(cfg: RunConfig, f: Fault) -> FaultReply:
        async with Client(cfg, tool_net(run_dir, cfg, None)) as c:
            return await c.fault(f)

    try:
        cfg = run_config_at(run_dir)
        f = make_fault(kind, list(targets))
        reply = asyncio.run(send(cfg, f))
    except (ControlError, ValueError) as e:  # what `kinswarm fault` says in one line, exit 2
        return {"returncode": 2, "said": f"kinswarm: {e}"}
    if reply.error:
        return {"returncode": 2, "said": f"kinswarm: fault refused: {reply.error}"}
    said = f"{cfg.run_id}: {describe(f)}: applied" + (f" ({reply.detail})" if reply.detail else "")
    return {"returncode": 0, "said": said}


def _rows(run_dir: Path) -> list[dict[str, Any]]:
    try:
        text = (run_dir / "metrics.jsonl").read_text()
    except OSError:
        return []
    return [json.loads(line) for line in text.splitlines() if line.strip()]


def swarm_run(run_file: Path, out: Path, lock_after: int | None = None, timeout: float = 1800) -> dict[str, Any]:
    """RUN_FILE's run into OUT as `kinswarm run RUN_FILE --out OUT` makes it (`main`, in a process of its own; the
    process placement, as the file says). `lock_after`: once that many epochs are in metrics.jsonl, the fault of
    `kinswarm fault OUT lock a2` is sent (`_fault`); where the sim applied it is read back from events.jsonl. Returns
    the epochs' final errors (and the lock's epoch and step)."""
    if out.exists():
        raise ValueError(f"{out}: exists; a run directory is made by the run")
    if lock_after is not None:
        import kinswarm.actors.control.client  # noqa: F401 -- imported now, not while the run goes by

    log = out.parent / f"{out.name}.log"  # the run's own output (a pipe nobody reads while it runs could fill)
    out.parent.mkdir(parents=True, exist_ok=True)
    with open(log, "w") as sink:
        proc = subprocess.Popen(_run_command(run_file, out), stdout=sink, stderr=subprocess.STDOUT)
        sent: dict[str, Any] | None = None
        try:
            t0 = time.monotonic()
            while lock_after is not None and sent is None and proc.poll() is None:
                if time.monotonic() - t0 > timeout:
                    raise RuntimeError(f"{out}: no {lock_after} epochs within {timeout:.0f} s")
                if len(_rows(out)) >= lock_after:
                    sent = _fault(out, "lock", "a2")
                else:
                    time.sleep(0.2)
            proc.wait(timeout=timeout)
        finally:
            if proc.poll() is None:  # ours: ended by its pid, its actors with it (the run stops them on SIGTERM)
                proc.terminate()
                proc.wait(timeout=60)
    if proc.returncode != 0:
        tail = log.read_text(errors="replace").strip().splitlines()[-1:]
        raise RuntimeError(f"the run of {run_file}: exit {proc.returncode}: {' '.join(tail)} ({log})")
    res: dict[str, Any] = {"final_errors": [float(r["final_error"]) for r in _rows(out)]}
    if lock_after is not None:
        events = [json.loads(x) for x in (out / "events.jsonl").read_text().splitlines() if x.strip()]
        landed = [e for e in events if e.get("event") == "lock" and e.get("target") == "a2"]
        res["fault"] = sent
        res["lock"] = {"epoch": landed[0]["epoch"], "step": landed[0]["step"]} if landed else None
    return res


def row(policy: Path, goals: Sequence[Goal], steps: int, out: Path, lock_after: int) -> dict[str, Any]:
    """The whole row: the swarm intact and with a2 locked live, the env intact and with a2 locked from step 0.

    `after`: the epochs after the lock's landing one (0-based indices into `goals`), all of them the env's locked
    episodes; the swarm's, the env's locked and the env's intact final errors on them, and whether swarm and env agree
    to the bit."""
    file = write_run_file(out / "onnx-swarm.toml", policy, goals, steps)
    env_intact, env_locked = env_finals(file), env_finals(file, LOCK)
    intact = swarm_run(file, out / "swarm-intact")
    live = swarm_run(file, out / "swarm-lock-a2", lock_after=lock_after)
    res: dict[str, Any] = {
        "goals": len(goals),
        "steps": steps,
        "lock_after": lock_after,
        "run_file": file.name,
        "env_intact": env_intact,
        "env_locked": env_locked,
        "swarm_intact": intact["final_errors"],
        "swarm_live": live["final_errors"],
        "intact_identical": intact["final_errors"] == env_intact,
        "fault": live["fault"],
        "lock": live["lock"],
    }
    if live["lock"] is not None and len(live["final_errors"]) == len(goals):
        first = _epoch_index(out / "swarm-lock-a2", live["lock"]["epoch"]) + 1
        after = list(range(first, len(goals)))
        res["after"] = after
        res["before_identical"] = live["final_errors"][: first - 1] == env_intact[: first - 1]
        res["after_identical"] = [live["final_errors"][i] for i in after] == [env_locked[i] for i in after]
    return res


def _epoch_index(run_dir: Path, epoch: int) -> int:
    """The position in metrics.jsonl (= in the goals) of the epoch an event names."""
    for i, r in enumerate(_rows(run_dir)):
        if r["epoch"] == epoch:
            return i
    raise RuntimeError(f"{run_dir}: epoch {epoch} of its events.jsonl is not in its metrics.jsonl")


def within(errors: Sequence[float], tol: float = 0.5) -> int:
    return int(sum(e <= tol for e in errors))


if __name__ == "__main__":
    sys.exit(main())
