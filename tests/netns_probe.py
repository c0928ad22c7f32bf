"""Run inside a test host (network namespace) by tests/test_deploy.py: try to join a secured swarm.

python netns_probe.py open   NETSPEC.json            -> prints "opened" or "refused: ..."
python netns_probe.py fault  NETSPEC.json RUN_DIR ID -> prints "reply: ..." or "no reply"
"""

from __future__ import annotations

import asyncio
import sys
import time
from pathlib import Path

from kinswarm.actors.files.config import load_run_config
from kinswarm.actors.runtime import NetSpec, Node, open_session
from kinswarm.protocol.keys import Keys
from kinswarm.protocol.messages import Fault, FaultReply


def try_open(spec: NetSpec) -> str:
    try:
        s = open_session(spec)
    except Exception as e:
        return f"refused: {e}"
    s.close()
    return "opened"


async def try_fault(spec: NetSpec, run_dir: Path, fid: str) -> str:
    """Send a correctly signed fault request (the run's key is known) as `spec`'s identity."""
    cfg = load_run_config(run_dir / "config.json")
    session = open_session(spec)
    node = Node(session, Keys(cfg.run_id), "cli", f"probe-{fid}", cfg.key)
    try:
        k = node.keys
        node.listen(k.rep("fault", fid))
        await asyncio.sleep(1.0)  # the session's links and declarations settle
        fault = Fault(id=fid, fault="lock", targets=["a3"], seconds=None, steps=None, rate=None, ms=None,
                      amplitude_deg=None)  # fmt: skip
        node.send(k.fault("request"), fault)
        deadline = time.monotonic() + 4.0
        while (left := deadline - time.monotonic()) > 0:
            try:
                key, payload = await node.recv(timeout=left)
            except TimeoutError:
                break
            reply = node.decode(key, payload, FaultReply)
            if reply is not None and reply.id == fid:
                return f"reply: {reply.error or reply.detail}"
        return "no reply"
    finally:
        node.close()
        session.close()


def main() -> int:
    mode, spec_path = sys.argv[1], Path(sys.argv[2])
    spec = NetSpec.from_json(spec_path.read_text())
    if mode == "open":
        print(try_open(spec), flush=True)
    else:
        print(asyncio.run(try_fault(spec, Path(sys.argv[3]), sys.argv[4])), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
