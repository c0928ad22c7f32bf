"""Test hosts on one machine: Linux network namespaces joined by veth pairs to a bridge (shared by the
cross-host tests and benchmarks/deploy_rate.py). Only addresses inside namespaces this module made.

    with Hosts(["brain", "limbs"]) as hosts:
        hosts.address("brain")                     # 10.X.Y.1
        p = hosts.spawn("brain", [kinswarm, "up", ...], log)
        hosts.cut("limbs"); ...; hosts.mend("limbs")
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import time
from pathlib import Path


class NetnsUnavailable(RuntimeError):
    pass


def _ip(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    return subprocess.run(["ip", *args], capture_output=True, text=True, timeout=10, check=check)


class Hosts:
    """Namespaces `<tag>-<name>` on a bridge in `<tag>-sw`; removed (with every process in them) on exit. `tag`
    tells apart two sets of hosts of one process (at most 3 characters: interface names are short)."""

    def __init__(self, names: list[str], tag: str = "") -> None:
        self.names = names
        pid = os.getpid()
        self.tag = f"ks{pid % 100000}{tag}"
        self.net = f"10.{100 + pid % 100}.{(pid // 100) % 250}"
        self.procs: list[subprocess.Popen] = []
        self.made: list[str] = []

    def ns(self, name: str) -> str:
        return f"{self.tag}-{name}"

    def address(self, name: str) -> str:
        return f"{self.net}.{self.names.index(name) + 1}"

    def __enter__(self) -> Hosts:
        if shutil.which("ip") is None:
            raise NetnsUnavailable("the `ip` command (iproute2) is not installed")
        if os.geteuid() != 0:
            raise NetnsUnavailable("network namespaces need root")
        try:
            self._add(f"{self.tag}-sw")
            sw = self.ns("sw")
            _ip("-n", sw, "link", "add", "br0", "type", "bridge")
            _ip("-n", sw, "link", "set", "br0", "up")
            for i, name in enumerate(self.names):
                ns = self.ns(name)
                self._add(ns)
                host_if, sw_if = f"v{i}", f"{self.tag}s{i}"
                _ip("link", "add", host_if + self.tag, "type", "veth", "peer", "name", sw_if)
                _ip("link", "set", host_if + self.tag, "netns", ns)
                _ip("link", "set", sw_if, "netns", sw)
                _ip("-n", ns, "link", "set", host_if + self.tag, "name", "eth0")
                _ip("-n", ns, "addr", "add", f"{self.address(name)}/24", "dev", "eth0")
                _ip("-n", ns, "link", "set", "eth0", "up")
                _ip("-n", ns, "link", "set", "lo", "up")
                _ip("-n", sw, "link", "set", sw_if, "master", "br0")
                _ip("-n", sw, "link", "set", sw_if, "up")
        except subprocess.CalledProcessError as e:
            self.__exit__(None, None, None)
            raise NetnsUnavailable(f"the kernel refused: {' '.join(e.cmd)}: {e.stderr.strip()}") from None
        return self

    def _add(self, ns: str) -> None:
        _ip("netns", "add", ns)
        self.made.append(ns)

    def spawn(self, name: str, argv: list[str], log: Path, env: dict[str, str] | None = None) -> subprocess.Popen:
        """A process inside host `name`, in its own process group, output to `log`."""
        with open(log, "ab") as f:
            p = subprocess.Popen(
                ["ip", "netns", "exec", self.ns(name), *argv],
                stdout=f,
                stderr=subprocess.STDOUT,
                stdin=subprocess.DEVNULL,
                start_new_session=True,
                env=env,
            )
        self.procs.append(p)
        return p

    def run(self, name: str, argv: list[str], timeout: float) -> subprocess.CompletedProcess:
        return subprocess.run(
            ["ip", "netns", "exec", self.ns(name), *argv], capture_output=True, text=True, timeout=timeout
        )

    def cut(self, name: str) -> None:
        """Take host `name`'s link down (its cable pulled)."""
        _ip("-n", self.ns(name), "link", "set", "eth0", "down")

    def mend(self, name: str) -> None:
        _ip("-n", self.ns(name), "link", "set", "eth0", "up")

    def _signal_running(self, sig: signal.Signals) -> None:
        for p in self.procs:
            if p.poll() is None:
                try:
                    os.killpg(p.pid, sig)
                except ProcessLookupError:
                    pass

    def __exit__(self, *exc: object) -> None:
        self._signal_running(signal.SIGTERM)
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline and any(p.poll() is None for p in self.procs):
            time.sleep(0.1)
        self._signal_running(signal.SIGKILL)
        for p in self.procs:
            p.wait()
        for ns in reversed(self.made):  # whatever still runs in them goes too
            pids = _ip("netns", "pids", ns, check=False).stdout.split()
            for pid in pids:
                try:
                    os.kill(int(pid), signal.SIGKILL)
                except (ProcessLookupError, ValueError):
                    pass
            _ip("netns", "del", ns, check=False)
        self.made.clear()
