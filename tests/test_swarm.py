"""The swarm end to end: real processes, real Zenoh sessions on loopback, the real PyBullet world."""

from __future__ import annotations

import dataclasses
import json
import math
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
import zenoh
from conftest import EXAMPLES, LOCKSTEP_ARGS, free_port, run_config, swarm_pids, tool_net
from kinswarm.actors.cli.commands import main as cli_main
from kinswarm.actors.runtime import open_session
from kinswarm.protocol.robots import load_robot
from kinswarm.sim import kinematics
from kinswarm.sim.baseline import greedy_increments, rule_increments

pytestmark = pytest.mark.timeout(180)


def run(args: list[str]) -> dict:
    assert cli_main(args + ["--no-progress"]) == 0
    out = Path(args[args.index("--out") + 1])
    return json.loads((out / "summary.json").read_text())


def test_single_run_leaves_its_files(tmp_path, chain4, endpoint):
    out = tmp_path / "r"
    s = run(
        [
            "run",
            str(chain4),
            "--placement",
            "single",
            "--epochs",
            "2",
            "--steps",
            "60",
            *LOCKSTEP_ARGS,
            "--listen",
            endpoint,
            "--out",
            str(out),
            "--seed",
            "3",
        ]
    )
    for f in (
        "config.json",
        "metrics.jsonl",
        "summary.json",
        "learning_curve.png",
        "arm.png",
        "agents/a1.npz",
        "agents/a4.npz",
    ):
        assert (out / f).is_file(), f
    assert s["epochs"] == 2 and s["steps_per_epoch"] == 60 and s["seed"] == 3
    assert s["placement"] == "single" and s["reward"] == "shaped"
    assert len(s["final_error"]) == len(s["mean_error"]) == 2
    assert s["steps_per_second"] > 0 and s["wall_seconds"] > 0 and s["missed_cmds"] == 0
    assert len((out / "metrics.jsonl").read_text().splitlines()) == 2


def test_process_and_single_give_the_same_run(tmp_path, chain4):
    common = ["--epochs", "3", "--steps", "120", "--seed", "11", *LOCKSTEP_ARGS]
    a = run(
        [
            "run",
            str(chain4),
            "--placement",
            "single",
            "--out",
            str(tmp_path / "s"),
            "--listen",
            f"tcp/127.0.0.1:{free_port()}",
            *common,
        ]
    )
    b = run(
        [
            "run",
            str(chain4),
            "--placement",
            "process",
            "--out",
            str(tmp_path / "p"),
            "--listen",
            f"tcp/127.0.0.1:{free_port()}",
            *common,
        ]
    )
    assert a["final_error"] == b["final_error"]
    assert a["mean_error"] == b["mean_error"]
    assert b["missed_cmds"] == 0
    assert swarm_pids(str(tmp_path / "p")) == []


def test_tree_runs_in_processes(tmp_path, tree5, endpoint):
    s = run(
        [
            "run",
            str(tree5),
            "--placement",
            "process",
            "--epochs",
            "2",
            "--steps",
            "50",
            *LOCKSTEP_ARGS,
            "--listen",
            endpoint,
            "--out",
            str(tmp_path / "t"),
        ]
    )
    assert s["missed_cmds"] == 0 and len(s["final_error"]) == 2


def _spam(run_id: str, out: Path, stop: threading.Event) -> int:
    """Publish garbage and ill-typed messages on every key of the run until told to stop: a process that may join the
    run's network (it read the run's files for its credentials) but holds no valid message, which the codec refuses."""
    import msgpack

    net = tool_net(out, stop)
    if net is None:
        return 0
    s = open_session(net)
    keys = [
        "a/a1/down",
        "a/a2/down",
        "a/a3/up",
        "a/a1/up",
        "sim/obs/a2",
        "sim/cmd/a4",
        "sim/task",
        "ctl/epoch",
        "ctl/checkpoint",
        "ctl/stop",
        "metrics/epoch",
        "rep/agent/a1",
        "sim/cmd/zz",
    ]
    junk = [
        b"\x00\xff garbage",
        msgpack.packb({"v": 1, "kind": "cmd", "run": run_id, "src": "x", "epoch": 0, "step": "NaN", "delta": 1e308}),
        msgpack.packb({"v": 99}),
        msgpack.packb({"v": 1, "kind": "stop", "run": run_id, "src": "x"}),
    ]
    pubs = [s.declare_publisher(f"ks/{run_id}/{k}", congestion_control=zenoh.CongestionControl.BLOCK) for k in keys]
    sent = 0
    while not stop.is_set():
        for p in pubs:
            for j in junk:
                p.put(j)
                sent += 1
        time.sleep(0.01)
    s.close()
    return sent


def test_malformed_messages_are_rejected_and_the_run_goes_on(tmp_path, chain4):
    common = ["run", str(chain4), "--placement", "process", "--epochs", "3", "--steps", "100", "--seed", "5"]
    common += LOCKSTEP_ARGS
    clean = run(common + ["--out", str(tmp_path / "clean"), "--listen", f"tcp/127.0.0.1:{free_port()}"])
    port = free_port()
    stop = threading.Event()
    sent: list[int] = []
    t = threading.Thread(target=lambda: sent.append(_spam("noisy", tmp_path / "noisy", stop)))
    # the spammer connects as soon as the supervisor listens (and has told its tools how)
    t.start()
    try:
        noisy = run(
            common + ["--out", str(tmp_path / "noisy"), "--listen", f"tcp/127.0.0.1:{port}", "--run-id", "noisy"]
        )
    finally:
        stop.set()
        t.join(10)
    assert sent and sent[0] > 100
    # garbage never touched learned state: the same seed gives the same run as without it
    assert clean["missed_cmds"] == 0 and noisy["missed_cmds"] == 0
    assert noisy["final_error"] == clean["final_error"]
    logs = "".join(p.read_text() for p in (tmp_path / "noisy" / "logs").glob("*.log"))
    assert "rejected message on ks/noisy/a/a2/down" in logs
    assert "rejected message on ks/noisy/sim/cmd/a4" in logs
    # unsigned junk is refused before it is even parsed (the codec's MAC)
    assert "too short" in logs and "bad MAC" in logs


def start_long_run(topology: Path, endpoint: str, out: Path) -> subprocess.Popen:
    """`kinswarm run` as a user starts it, long enough to be stopped from outside."""
    return subprocess.Popen(
        [
            sys.executable,
            "-m",
            "kinswarm.actors.cli",
            "run",
            str(topology),
            "--epochs",
            "1000",
            "--steps",
            "200",
            "--listen",
            endpoint,
            "--out",
            str(out),
            "--no-progress",
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )


def test_ctrl_c_stops_everything(tmp_path, chain4, endpoint):
    out = tmp_path / "c"
    p = start_long_run(chain4, endpoint, out)
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            m = out / "metrics.jsonl"
            if m.exists() and m.read_text().count("\n") >= 1:
                break
            time.sleep(0.1)
        assert len(swarm_pids(str(out))) == 8  # supervisor + hub + zygote + sim + 4 agents
        p.send_signal(signal.SIGINT)
        time.sleep(0.3)  # into the shutdown (it waits up to 3 s for the actors' byes)
        p.send_signal(signal.SIGINT)  # an impatient second Ctrl-C does not cut it short
        p.wait(timeout=30)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 130
    time.sleep(0.2)
    assert swarm_pids(str(out)) == []
    s = json.loads((out / "summary.json").read_text())
    assert s["interrupted"] is True and s["epochs"] >= 1
    assert (out / "learning_curve.png").exists() and (out / "arm.png").exists()


def test_killed_supervisor_leaves_no_orphans(tmp_path, chain4, endpoint):
    out = tmp_path / "k"
    p = start_long_run(chain4, endpoint, out)
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and len(swarm_pids(str(out))) < 8:
            time.sleep(0.1)
        assert len(swarm_pids(str(out))) == 8
        p.send_signal(signal.SIGKILL)
        p.wait(timeout=10)
        deadline = time.monotonic() + 15
        while time.monotonic() < deadline and swarm_pids(str(out)):
            time.sleep(0.1)
        assert swarm_pids(str(out)) == []
    finally:
        for pid in swarm_pids(str(out)):
            os.kill(pid, signal.SIGKILL)


def test_from_checkpoint_evaluates_greedily_and_deterministically(tmp_path, chain4):
    train = tmp_path / "train"
    run(
        [
            "run",
            str(chain4),
            "--placement",
            "single",
            "--epochs",
            "3",
            "--steps",
            "150",
            "--listen",
            f"tcp/127.0.0.1:{free_port()}",
            "--out",
            str(train),
        ]
    )
    evals = [
        run(
            [
                "run",
                str(chain4),
                "--placement",
                "single",
                "--epochs",
                "2",
                "--steps",
                "150",
                "--from",
                str(train),
                "--learn",
                "off",
                "--explore",
                "off",
                "--listen",
                f"tcp/127.0.0.1:{free_port()}",
                "--out",
                str(tmp_path / f"e{i}"),
                "--seed",
                str(i),
            ]
        )
        for i in range(2)
    ]
    # frozen and greedy: every epoch repeats, whatever the seed (ties aside, which greedy breaks at random)
    assert evals[0]["learn"] is False and evals[0]["explore"] is False
    assert not (tmp_path / "e0" / "agents").exists()  # evaluation writes no checkpoints


def test_bad_checkpoint_is_refused_before_start(tmp_path, chain4, capsys):
    (tmp_path / "agents").mkdir()
    (tmp_path / "agents" / "a1.npz").write_bytes(b"not a checkpoint")
    rc = cli_main(["run", str(chain4), "--from", str(tmp_path), "--out", str(tmp_path / "o"), "--no-progress"])
    assert rc == 2
    assert "a1.npz" in capsys.readouterr().err


def test_baseline_reaches_the_goal(tmp_path, chain4, endpoint):
    s = run(
        [
            "baseline",
            str(chain4),
            "--placement",
            "process",
            "--epochs",
            "1",
            "--steps",
            "80",
            "--listen",
            endpoint,
            "--out",
            str(tmp_path / "b"),
        ]
    )
    assert s["controller"] == "pinv"
    assert s["final_error"][0] < 0.01
    assert (tmp_path / "b" / "arm.png").is_file()


@pytest.mark.parametrize("law", ["greedy", "rule"])
def test_reference_laws_drive_the_world_as_the_model_says(tmp_path, chain4, endpoint, law):
    """`kinswarm baseline --law greedy|rule` over the wire ends where the model's replay of its law ends."""
    args = ["baseline", str(chain4), "--law", law, "--placement", "single", "--epochs", "1"]
    s = run([*args, "--steps", "150", "--listen", endpoint, "--out", str(tmp_path / "g")])
    assert s["controller"] == law
    topo, goal = load_robot(chain4), (4.16, 6.18)
    q = topo.initial_angles()
    increments = {"greedy": greedy_increments, "rule": rule_increments}[law]
    for _ in range(150):
        dq = increments(topo, q, goal)
        q = {a: q[a] + dq[a] for a in q}
    ((x, y, _),) = kinematics.tips(topo, q).values()
    assert s["final_error"][0] == pytest.approx(math.dist((x, y), goal), abs=1e-6)
    assert s["final_error"][0] < 1.0


def test_bad_robot_is_a_clear_error(tmp_path, capsys):
    p = tmp_path / "t.toml"
    p.write_text('[robot]\n[[robot.agent]]\nid = "a"\nlink_length = 0\n[task]\nkind = "reach"\ngoal = [1, 1]\n')
    assert cli_main(["run", str(p), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "t.toml" in err and "robot.agent[0].link_length" in err and "Traceback" not in err


@pytest.mark.parametrize(("lease", "why"), [("50", "lease_ms: expected an integer >= 100"), ("90000", "at most 60000")])
def test_bad_lease_is_a_clear_error(tmp_path, chain4, capsys, lease, why):
    assert cli_main(["run", str(chain4), "--lease-ms", lease, "--out", str(tmp_path / "x"), "--no-progress"]) == 2
    assert why in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_config_round_trip(tmp_path):
    from kinswarm.actors.files.config import ConfigError, load_run_config

    cfg = run_config(EXAMPLES / "chain4.toml", run_id="x", out=str(tmp_path))
    cfg.write(tmp_path / "c.json")
    assert load_run_config(tmp_path / "c.json") == cfg
    with pytest.raises(ConfigError, match="placement"):
        dataclasses.replace(cfg, placement="bogus")


def test_successive_epochs_start_where_the_last_ended(tmp_path, chain4, endpoint):
    out = tmp_path / "s"
    args = ["run", str(chain4), "--placement", "single", "--epochs", "2", "--steps", "100", "--seed", "1"]
    run([*args, "--successive", "--listen", endpoint, "--out", str(out)])
    assert json.loads((out / "config.json").read_text())["successive"] is True
    e0, e1 = [json.loads(line) for line in (out / "metrics.jsonl").read_text().splitlines()]
    assert e0["final_error"] < e0["errors"][0] - 1  # the first epoch moved: a reset would be told apart
    # one step moves the tip at most (12 + 9 + 6 + 3) x 1 deg = 0.52 from where epoch 0 left it
    assert abs(e1["errors"][0] - e0["final_error"]) <= 0.53
