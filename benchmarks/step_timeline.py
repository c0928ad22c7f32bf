"""Where a step's time goes: when each message of a 4-joint-chain step arrives, after the step's `sim/task`.

    python benchmarks/step_timeline.py [--placement process|single] [--epochs 3] [--steps 500]

Runs `kinswarm run examples/chain4.toml` as a child process and, from a second Zenoh session, records the arrival
time of every step message (`sim/*`, `a/*`). Steps are cut at each `sim/task`; the first epoch is dropped as
warm-up. Prints, per key, the median delay after the task (a message to agent X is `a/X/down` from its parent
or `a/X/up` from a child; `sim/cmd/X` is agent X's action) and the median step period. The observer adds its own
delivery to every message: the offsets are for comparing stages, not absolute; in `single` placement it also
makes every put leave the process (about half the rate).
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from kinswarm.actors.runtime import open_session
from step_rate import free_port  # benchmarks/ is this script's directory, so first on sys.path

ROOT = Path(__file__).resolve().parent.parent
RUN_ID = "timeline"


def record(placement: str, epochs: int, steps: int) -> list[tuple[int, str]]:
    """(perf_counter_ns, key below the run's root) of every step message of one run."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    log: list[tuple[int, str]] = []
    prefix = f"ks/{RUN_ID}/"

    def keep(sample: Any) -> None:  # zenoh thread: only append
        log.append((time.perf_counter_ns(), str(sample.key_expr)[len(prefix) :]))

    with tempfile.TemporaryDirectory() as out:
        cmd = [sys.executable, "-m", "kinswarm.actors.cli", "run", str(ROOT / "examples" / "chain4.toml")]
        cmd += ["--placement", placement, "--epochs", str(epochs), "--steps", str(steps)]
        cmd += ["--run-id", RUN_ID, "--listen", endpoint, "--out", out, "--no-progress"]
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        session = None
        try:
            time.sleep(1.0)  # the supervisor's listener is up before its actors start stepping
            session = open_session(connect=(endpoint,))
            subs = [session.declare_subscriber(prefix + k, keep) for k in ("sim/**", "a/**")]
            _, err = proc.communicate(timeout=600)
            for s in subs:
                s.undeclare()
            if proc.returncode != 0:
                raise SystemExit(f"kinswarm run failed ({proc.returncode}):\n{err[-2000:]}")
        finally:
            if proc.poll() is None:
                proc.terminate()
                proc.wait(timeout=30)
            if session is not None:
                session.close()
    return log


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--placement", choices=("process", "single"), default="process")
    ap.add_argument("--epochs", type=int, default=3)
    ap.add_argument("--steps", type=int, default=500)
    a = ap.parse_args()
    if a.epochs < 2:
        ap.error("--epochs must be at least 2 (the first is dropped as warm-up)")
    log = record(a.placement, a.epochs, a.steps)
    cut: list[dict[str, int]] = []  # per step: first arrival of each key, and t0 = the task's
    for t, key in log:
        if key == "sim/task":
            cut.append({"t0": t})
        elif cut and key not in cut[-1]:
            cut[-1][key] = t
    longest = max(map(len, cut), default=0)
    whole = [s for s in cut if len(s) == longest]  # every message of the step seen
    kept = whole[len(whole) // a.epochs :]
    if len(kept) < 2:
        raise SystemExit(
            f"too few complete steps observed ({len(kept)}): the observer joins about a second after the run "
            "starts, and a short `single` run can be over by then; give it more --epochs or --steps"
        )
    period = statistics.median((b["t0"] - s["t0"]) / 1e3 for s, b in zip(kept, kept[1:], strict=False))
    delays = {k: statistics.median((s[k] - s["t0"]) / 1e3 for s in kept if k in s) for k in kept[0] if k != "t0"}
    print(f"{a.placement} placement, 4-joint chain: {len(kept)} steps after the first epoch")
    print(f"{'message':24}{'median µs after sim/task':>26}")
    for k, v in sorted(delays.items(), key=lambda kv: kv[1]):
        late = "  (the next step's: sent before its task)" if v > 0.9 * period else ""
        print(f"{k:24}{v:26.0f}{late}")
    print(f"step period median {period:.0f} µs = {1e6 / period:.0f} steps/s (with this observer)")


if __name__ == "__main__":
    main()
