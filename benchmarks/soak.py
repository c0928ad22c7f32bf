"""Soak: kill a random agent every N seconds through a long training run, then compare with the
fault-free run of the same seed.

    python benchmarks/soak.py [--every 5] [--epochs 60] [--steps 500] [--seed 0] [--placement process]

Both runs are `kinswarm run` child processes (real processes, real Zenoh sessions); the kills go
through `kinswarm fault RUN kill AGENT` exactly as a user types it. Prints restarts per agent, the
commands lost to deadlines (a held joint for one step each), the time each restart took (exit to
liveliness back), and the learning outcome of both runs.
"""

from __future__ import annotations

import argparse
import json
import random
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
CLI = [sys.executable, "-m", "kinswarm.actors.cli"]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start(out: Path, run_id: str, a: argparse.Namespace) -> subprocess.Popen:
    argv = [*CLI, "run", str(ROOT / "examples" / "chain4.toml"), "--epochs", str(a.epochs), "--steps", str(a.steps)]
    argv += ["--seed", str(a.seed), "--placement", a.placement, "--run-id", run_id, "--out", str(out)]
    argv += ["--listen", f"tcp/127.0.0.1:{free_port()}", "--no-progress"]
    return subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)


def outcome(out: Path) -> dict:
    s = json.loads((out / "summary.json").read_text())
    last = s["final_error"][-20:]
    return {
        "success": sum(e <= 0.5 for e in last) / len(last),
        "median": statistics.median(last),
        "missed": s["missed_cmds"],
        "wall": s["wall_seconds"],
        "restarts": s.get("restarts", {}),
        "error": s.get("error", ""),
    }


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--every", type=float, default=5.0, help="seconds between kills")
    p.add_argument("--epochs", type=int, default=60)
    p.add_argument("--steps", type=int, default=500)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--placement", choices=("process", "single"), default="process")
    a = p.parse_args()
    rng = random.Random(a.seed)
    with tempfile.TemporaryDirectory() as d:
        base, soak = Path(d) / "fault-free", Path(d) / "soak"
        proc = start(base, "soak-base", a)
        proc.communicate()
        proc = start(soak, "soak", a)
        kills: list[str] = []
        while proc.poll() is None:
            time.sleep(a.every)
            if proc.poll() is not None or not (soak / "metrics.jsonl").exists():
                continue
            agent = rng.choice(["a1", "a2", "a3", "a4"])
            r = subprocess.run([*CLI, "fault", "soak", "kill", agent, "--run-dir", str(soak)], capture_output=True)
            if r.returncode == 0:
                kills.append(agent)
        text = proc.communicate()[0].decode()
        if proc.returncode != 0:
            print(text)
        events = [json.loads(line) for line in (soak / "events.jsonl").read_text().splitlines()]
        took = []
        for e in events:
            if e["event"] == "exited":
                back = [
                    b["t"] for b in events if b["event"] == "alive" and b["target"] == e["target"] and b["t"] > e["t"]
                ]
                if back:
                    took.append(back[0] - e["t"])
        f, s = outcome(base), outcome(soak)
    print(
        f"\nsoak: {len(kills)} kills, one every {a.every:g} s, {a.epochs} epochs x {a.steps} steps, seed {a.seed}, "
        f"{a.placement} placement"
    )
    print("| run | last-20 within 0.5 | median final error | cmds lost to deadlines | wall s | restarts |")
    print("|---|---|---|---|---|---|")
    for name, o in (("fault-free", f), ("soak", s)):
        restarts = sum(o["restarts"].values())
        print(f"| {name} | {o['success']:.0%} | {o['median']:.3f} | {o['missed']} | {o['wall']:.0f} | {restarts} |")
    if took:
        print(f"restart time (exit -> alive): median {statistics.median(took):.2f} s, max {max(took):.2f} s")
    if s["error"]:
        print(f"the soak run failed: {s['error']}")
    return 0 if not s["error"] else 1


if __name__ == "__main__":
    sys.exit(main())
