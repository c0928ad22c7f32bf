"""Recovery from a network cut, over many trials: the 4-joint chain split over two hosts (network
namespaces on a bridge: the sim and the root on `brain`, a2-a4 on `limbs`), limbs' link taken down for
`--cut` seconds once training runs, then brought back.

    sudo python benchmarks/cut_recovery.py [--trials 10] [--cut 10] [--epochs 6] [--steps 300]

Per trial: whether the run completed every epoch, how long each side took to record the partition after
the cut, how long after the link came back the leader recorded the rejoin, how many steps the sim took
between the leader's detection and its hold, and the commands missed in the run. Prints a table, then the
count of completed runs and the medians. Needs root (network namespaces).
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "benchmarks"))
from deploy_rate import start_split  # noqa: E402
from netns import Hosts  # noqa: E402


@dataclass
class Trial:
    completed: bool
    detect_brain_s: float
    detect_limbs_s: float
    rejoin_s: float  # leader's rejoin after the link came back
    hold_steps: int  # steps between the leader's partition and the sim's pause
    missed_cmds: int
    wall_s: float


def _events(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines()] if path.exists() else []


def _first(ev: list[dict], event: str, target: str | None = None) -> dict | None:
    return next((e for e in ev if e["event"] == event and (target is None or e["target"] == target)), None)


def trial(cut_s: float, epochs: int, steps: int, seed: int) -> Trial:
    nan = float("nan")
    with tempfile.TemporaryDirectory() as d, Hosts(["brain", "limbs"]) as h:
        tmp = Path(d)
        t0 = time.monotonic()
        leader = start_split(h, tmp, epochs, steps, seed)
        metrics = tmp / "brain" / "metrics.jsonl"
        while not (metrics.exists() and metrics.read_text().strip()):  # training has begun
            if leader.poll() is not None or time.monotonic() - t0 > 120:
                raise SystemExit(f"the run did not start; its log:\n{(tmp / 'b.log').read_text()[-2000:]}")
            time.sleep(0.2)
        time.sleep(0.5)
        cut = time.time()
        h.cut("limbs")
        time.sleep(cut_s)
        mended = time.time()
        h.mend("limbs")
        try:
            code = leader.wait(timeout=120 + epochs * steps / 20)
        except subprocess.TimeoutExpired:
            code = None
            leader.kill()
        wall = time.monotonic() - t0
        rows = [json.loads(line) for line in metrics.read_text().splitlines()]
        brain, limbs = _events(tmp / "brain" / "events.jsonl"), _events(tmp / "limbs" / "events.jsonl")
        pb, pl = _first(brain, "partition", "limbs"), _first(limbs, "partition", "brain")
        back, pause = _first(brain, "rejoin", "limbs"), _first(brain, "pause")
        return Trial(
            completed=code == 0 and len(rows) == epochs,
            detect_brain_s=pb["wall"] - cut if pb else nan,
            detect_limbs_s=pl["wall"] - cut if pl else nan,
            rejoin_s=back["wall"] - mended if back else nan,
            hold_steps=pause["step"] - pb["step"] if pause and pb else -1,
            missed_cmds=sum(r.get("missed_cmds", 0) for r in rows),
            wall_s=wall,
        )


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--trials", type=int, default=10)
    p.add_argument("--cut", type=float, default=10.0, help="seconds the link stays down")
    p.add_argument("--epochs", type=int, default=6)
    p.add_argument("--steps", type=int, default=300)
    a = p.parse_args()
    print("| trial | completed | brain detects (s) | limbs detects (s) | rejoin after mend (s) | hold (steps) "
          "| missed cmds | wall (s) |\n|---|---|---|---|---|---|---|---|")  # fmt: skip
    done: list[Trial] = []
    for i in range(a.trials):
        t = trial(a.cut, a.epochs, a.steps, seed=i)
        done.append(t)
        print(f"| {i} | {'yes' if t.completed else 'NO'} | {t.detect_brain_s:.2f} | {t.detect_limbs_s:.2f} | "
              f"{t.rejoin_s:.2f} | {t.hold_steps} | {t.missed_cmds} | {t.wall_s:.0f} |", flush=True)  # fmt: skip

    def med(xs: list[float]) -> str:
        xs = [x for x in xs if x == x]
        return f"{statistics.median(xs):.2f}" if xs else "-"

    print(f"\ncompleted {sum(t.completed for t in done)} of {len(done)} runs with a {a.cut:.0f} s cut")
    print(f"median detection: brain {med([t.detect_brain_s for t in done])} s, "
          f"limbs {med([t.detect_limbs_s for t in done])} s; median rejoin {med([t.rejoin_s for t in done])} s; "
          f"median missed commands {med([float(t.missed_cmds) for t in done])}")  # fmt: skip
    return 0 if all(t.completed for t in done) else 1


if __name__ == "__main__":
    sys.exit(main())
