"""How long `kinswarm fault` and `kinswarm status` take on a live run, against the floor of starting Python at all.

    python benchmarks/control_latency.py [--repeats 7] [--placement process]

Starts a 4-joint chain that outlasts the measurement, then, alternating in each round: `python -c pass` and
`python -c "import zenoh"` (the floor), `kinswarm fault RUN lock a2` / `free a2` and `kinswarm status RUN` as a user
types them (the console script next to this Python), the same fault through the whole CLI (commands.main, the path
every command took before fault and status had a lean one), and the imports of each path (`-X importtime`: the
cumulative time of every module the command imported at top level). Medians, min and max over the rounds, with the
machine's load average at the start and the end: on a shared machine quote medians and the ratios to the floor of
the same sitting, never a lone number.
"""

from __future__ import annotations

import argparse
import os
import re
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PY = sys.executable
KINSWARM = str(Path(PY).with_name("kinswarm"))
WHOLE_CLI = "import sys; from kinswarm.actors.cli.commands import main; sys.exit(main())"
_TOP = re.compile(r"^import time:\s+\d+ \|\s+(\d+) \| \S")  # a module imported at top level: its cumulative µs


def _port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wall(argv: list[str]) -> float:
    t0 = time.perf_counter()
    r = subprocess.run(argv, capture_output=True, text=True, timeout=600)
    took = time.perf_counter() - t0
    if r.returncode != 0:
        raise SystemExit(f"{' '.join(argv)} failed ({r.returncode}): {r.stderr.strip() or r.stdout.strip()}")
    return took


def _imports(argv: list[str]) -> float:
    """Seconds the command spent importing (what `-X importtime` counts at top level)."""
    r = subprocess.run([PY, "-X", "importtime", *argv], capture_output=True, text=True, timeout=600)
    if r.returncode != 0:
        raise SystemExit(f"{' '.join(argv)} failed ({r.returncode}): {r.stderr.strip()[-500:]}")
    return sum(int(m.group(1)) for line in r.stderr.splitlines() if (m := _TOP.match(line))) / 1e6


def _start(out: Path, placement: str) -> subprocess.Popen:
    argv = [KINSWARM, "run", str(ROOT / "examples" / "chain4.toml"), "--placement", placement, "--epochs", "100000"]
    argv += [
        "--steps",
        "200",
        "--run-id",
        "ctl",
        "--out",
        str(out),
        "--listen",
        f"tcp/127.0.0.1:{_port()}",
        "--no-progress",
    ]
    argv += ["--set", "run.record=false", "--checkpoint-every", "0"]
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    while not (out / "metrics.jsonl").exists() or not (out / "metrics.jsonl").read_text().strip():
        if proc.poll() is not None:
            raise SystemExit(f"the run ended before training ({proc.returncode}): see {out}/logs")
        time.sleep(0.1)
    return proc


def _stop(proc: subprocess.Popen) -> None:
    os.killpg(proc.pid, signal.SIGINT)
    try:
        proc.wait(timeout=60)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--placement", choices=("process", "single"), default="process")
    a = ap.parse_args()
    load0 = os.getloadavg()
    rows: dict[str, list[float]] = {}

    def add(name: str, value: float) -> None:
        rows.setdefault(name, []).append(value)

    with tempfile.TemporaryDirectory() as d:
        out = Path(d) / "ctl"
        proc = _start(out, a.placement)
        try:
            run = ["--run-dir", str(out)]
            for i in range(a.repeats):
                verb = "lock" if i % 2 == 0 else "free"  # lock, then free again: the run stays as it was
                add("python -c pass", _wall([PY, "-c", "pass"]))
                add('python -c "import zenoh"', _wall([PY, "-c", "import zenoh"]))
                add("kinswarm fault RUN lock|free a2", _wall([KINSWARM, "fault", "ctl", verb, "a2", *run]))
                add("kinswarm status RUN", _wall([KINSWARM, "status", "ctl", *run]))
                add("whole CLI: fault RUN free a2", _wall([PY, "-c", WHOLE_CLI, "fault", "ctl", "free", "a2", *run]))
                entry = ["-m", "kinswarm.actors.cli.entry"]
                add("imports: fault (lean path)", _imports([*entry, "fault", "ctl", "free", "a2", *run]))
                add("imports: status (lean path)", _imports([*entry, "status", "ctl", *run]))
                add("imports: fault (whole CLI)", _imports(["-c", WHOLE_CLI, "fault", "ctl", "free", "a2", *run]))
                add("imports: zenoh", _imports(["-c", "import zenoh"]))
        finally:
            _stop(proc)
    load1 = os.getloadavg()
    floor = statistics.median(rows["python -c pass"])
    zfloor = statistics.median(rows['python -c "import zenoh"'])
    print(
        f"{os.cpu_count()} cores, load average {load0[0]:.1f} at the start, {load1[0]:.1f} at the end, "
        f"{a.repeats} rounds"
    )
    print(f"{'':36}{'median s':>10}{'min':>8}{'max':>8}{'/ pass':>8}{'/ zenoh':>9}")
    for name, v in rows.items():
        med = statistics.median(v)
        print(f"{name:36}{med:10.3f}{min(v):8.3f}{max(v):8.3f}{med / floor:8.1f}{med / zfloor:9.2f}")


if __name__ == "__main__":
    main()
