"""The paper's §5.3 robustness scenarios after training, in four conditions, over seeds.

    python experiments/robustness.py [--seeds 3] [--train-epochs 60] [--steps 1500] [--out DIR]

For each seed: train a swarm on examples/chain4.toml (`kinswarm run`, single placement, default
settings), then run each scenario file in scenarios/ for one trial of --steps steps as
  frozen     the trained swarm, learning and exploration off (`--from T --learn off --explore off`)
  learning   the trained swarm still learning (`--from T`)
  scratch    an untrained swarm learning from scratch within the trial (the control)
  baseline   the pseudo-inverse controller (`kinswarm baseline`)
and print the final end-effector error of each (mean ± std over seeds, and per seed). Every run
leaves its directory (metrics, events.jsonl, tracking.png) under --out.
"""

from __future__ import annotations

import argparse
import json
import socket
import statistics
import time
from pathlib import Path

from kinswarm.actors.cli import main as kinswarm

ROOT = Path(__file__).resolve().parent.parent
CHAIN = ROOT / "examples" / "chain4.toml"
SCENARIOS = sorted((ROOT / "scenarios").glob("paper-*.toml"))
CONDITIONS = ("frozen", "learning", "scratch", "baseline")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def run(*args: str | Path) -> dict:
    argv = [str(a) for a in args] + [
        "--placement",
        "single",
        "--no-progress",
        "--listen",
        f"tcp/127.0.0.1:{free_port()}",
    ]
    code = kinswarm(argv)
    if code != 0:
        raise SystemExit(f"kinswarm {' '.join(argv)} failed with {code}")
    out = Path(argv[argv.index("--out") + 1])
    return json.loads((out / "summary.json").read_text())


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--seeds", type=int, default=3)
    p.add_argument("--train-epochs", type=int, default=60)
    p.add_argument("--steps", type=int, default=1500)
    p.add_argument("--out", type=Path, default=Path("runs/robustness"))
    a = p.parse_args()
    t0 = time.perf_counter()
    finals: dict[tuple[str, str], list[float]] = {}
    for seed in range(a.seeds):
        trained = a.out / f"train-s{seed}"
        s = run("run", CHAIN, "--epochs", a.train_epochs, "--seed", seed, "--out", trained)
        print(f"seed {seed}: trained {a.train_epochs} epochs, last final error {s['final_error'][-1]:.3f}")
        for sc in SCENARIOS:
            name = sc.stem
            common = ["--epochs", "1", "--steps", a.steps, "--seed", seed, "--scenario", sc]
            for cond in CONDITIONS:
                out = a.out / f"{name}-{cond}-s{seed}"
                if cond == "frozen":
                    r = run(
                        "run", CHAIN, *common, "--from", trained, "--learn", "off", "--explore", "off", "--out", out
                    )
                elif cond == "learning":
                    r = run("run", CHAIN, *common, "--from", trained, "--out", out)
                elif cond == "scratch":
                    r = run("run", CHAIN, *common, "--out", out)
                else:
                    r = run("baseline", CHAIN, *common, "--out", out)
                finals.setdefault((name, cond), []).append(r["final_error"][-1])
                print(f"  {name:28s} {cond:9s} final error {r['final_error'][-1]:.3f}")
    print(f"\nfinal end-effector error after {a.steps} steps, {a.seeds} seeds ({time.perf_counter() - t0:.0f} s)")
    print(f"| scenario | {' | '.join(CONDITIONS)} |")
    print("|---|" + "---|" * len(CONDITIONS))
    for sc in SCENARIOS:
        cells = []
        for cond in CONDITIONS:
            v = finals[(sc.stem, cond)]
            sd = statistics.stdev(v) if len(v) > 1 else 0.0
            cells.append(f"{statistics.mean(v):.3f} ± {sd:.3f}")
        print(f"| {sc.stem} | {' | '.join(cells)} |")
    table = {f"{k[0]}/{k[1]}": v for k, v in finals.items()}
    (a.out / "results.json").write_text(json.dumps(table, indent=2) + "\n")


if __name__ == "__main__":
    main()
