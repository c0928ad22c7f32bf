"""The PyBullet robot world: a kinematic planar chain or tree loaded from a generated URDF, or a robot's own URDF
(a spatial robot, protocol/urdf_robot.py: its joints found by name, the joints that are not agents held at their
value, the tips its leaves' link frames with their tool frames on).

Joints are set kinematically (resetJointStatesMultiDof) -- discrete 1-degree increments need no dynamics,
and stepSimulation would only converge asymptotically. Every call passes physicsClientId, so several
Worlds coexist in one process.
"""

from __future__ import annotations

import math
import os
import shutil
import sys
import tempfile
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from types import TracebackType

from kinswarm.protocol import frames
from kinswarm.protocol.topology import Topology
from kinswarm.sim import urdf


@contextmanager
def _quiet_fd2() -> Iterator[None]:
    """PyBullet's banner is printed by C code to file descriptor 2; only redirecting the fd silences it."""
    sys.stderr.flush()
    saved = os.dup(2)
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(devnull)


with _quiet_fd2():
    import pybullet as pb

Pose = tuple[float, ...]  # a planar robot's tip (x, y, heading); a spatial one's a 7-float frame


def _joints_by_name(body: int, client: int) -> dict[str, int]:
    return {
        pb.getJointInfo(body, j, physicsClientId=client)[1].decode(): j
        for j in range(pb.getNumJoints(body, physicsClientId=client))
    }


def _load_planar(topo: Topology, path: Path, client: int) -> tuple[int, dict[str, int]]:
    """The generated URDF of a planar robot, its base at (x, y) turned by its heading."""
    bx, by, bh = topo.base
    body = pb.loadURDF(
        str(path),
        basePosition=(bx, by, 0.0),
        baseOrientation=pb.getQuaternionFromEuler((0.0, 0.0, bh)),
        useFixedBase=True,
        physicsClientId=client,
    )
    return body, _joints_by_name(body, client)


def _load_spatial(topo: Topology, path: Path, client: int) -> tuple[int, dict[str, int]]:
    """A robot's own URDF, fixed at its base frame; the joints that are not agents set to the value they hold."""
    with _quiet_fd2():  # PyBullet prints what it makes of the file's inertias and materials
        body = pb.loadURDF(
            str(path),
            basePosition=topo.base[:3],
            baseOrientation=topo.base[3:7],
            useFixedBase=True,
            physicsClientId=client,
        )
    by_name = _joints_by_name(body, client)
    for name, value in topo.held:
        pb.resetJointState(body, by_name[name], value, physicsClientId=client)
    return body, by_name


class World:
    """One PyBullet DIRECT client holding one fixed-base robot built from `topo`.

    Joint angles are kept in a double-precision cache that mirrors what was last written to PyBullet
    (reset and apply_increments are the only writers); tip poses are read back from PyBullet.
    """

    def __init__(
        self, topo: Topology, *, urdf_dir: Path | None = None, radius: float = 0.1, beside: World | None = None
    ) -> None:
        """`beside`: another world of the same robot whose PyBullet client this one's robot joins (a fleet in free
        space: a client costs ~28 MB and ~45 ms to connect, a body in one a fraction); it owns the client."""
        self.topo = topo
        self._tmpdir: str | None = None
        self._written: Path | None = None  # the URDF this world generated (a spatial robot's own file is not)
        self.client = -1
        self._owner = beside is None
        self.radius = radius  # the links' capsule radius (a planar robot's)
        if beside is not None:
            self.urdf_path, self.client = beside.urdf_path, beside.client
        elif topo.spatial:
            self.urdf_path = Path(topo.urdf)
        else:
            if urdf_dir is None:
                self._tmpdir = tempfile.mkdtemp(prefix="kinswarm-urdf-")
                urdf_dir = Path(self._tmpdir)
            self.urdf_path = self._written = urdf.write_urdf(topo, urdf_dir, radius=radius)
        if self._owner:
            with _quiet_fd2():
                self.client = pb.connect(pb.DIRECT)
        if self.client < 0:
            raise RuntimeError("pybullet.connect(DIRECT) failed")
        try:
            load = _load_spatial if topo.spatial else _load_planar
            self.body, by_name = load(topo, self.urdf_path, self.client)
            # Link index == index of the joint that creates it.
            self.joint_index: dict[str, int] = {
                a: by_name[topo.agents[a].joint if topo.spatial else urdf.joint_name(a)] for a in topo.order
            }
            self.agent_of_joint: dict[int, str] = {j: a for a, j in self.joint_index.items()}
            self._dof = topo.dof_agents
            self._dof_idx = [self.joint_index[a] for a in self._dof]
            self._limits = {a: topo.agents[a].limits for a in self._dof}
            self._leaves = topo.end_effectors
            # A spatial leaf's tip is its tool frame on its own link frame; a planar leaf has a tip link.
            self._tools = [topo.agents[leaf].tool for leaf in self._leaves] if topo.spatial else None
            self._tip_idx = [
                self.joint_index[leaf] if topo.spatial else by_name[urdf.tip_joint_name(leaf)] for leaf in self._leaves
            ]
            self._q: dict[str, float] = {}
            self.reset()
        except BaseException:
            self.close()
            raise

    def reset(self, angles: Mapping[str, float] | None = None) -> None:
        """Set every DOF joint to `angles` (all DOF agents, within limits); default topo.initial_angles()."""
        angles = self.topo.initial_angles() if angles is None else angles
        missing = set(self._dof) - set(angles)
        unknown = set(angles) - set(self._dof)
        if missing or unknown:
            raise ValueError(f"reset angles: missing {sorted(missing)}, not DOF agents {sorted(unknown)}")
        q = {}
        for a in self._dof:
            v = float(angles[a])
            lo, hi = self._limits[a]
            if not lo <= v <= hi:
                raise ValueError(f"reset angle for {a!r}: {v} outside limits [{lo}, {hi}]")
            q[a] = v
        self._write(q)

    def _write(self, q: dict[str, float]) -> None:
        pb.resetJointStatesMultiDof(
            self.body,
            self._dof_idx,
            targetValues=[[q[a]] for a in self._dof],
            targetVelocities=[[0.0]] * len(self._dof),
            physicsClientId=self.client,
        )
        self._q = q

    def joint_positions(self) -> dict[str, float]:
        """Current angle (rad) of every DOF agent."""
        return dict(self._q)

    def apply_increments(self, deltas: Mapping[str, float]) -> dict[str, float]:
        """q += delta clipped to the joint limits; agents left out hold. Returns the increment actually
        applied for every DOF agent (0.0 for those that held or sat at a limit)."""
        unknown = set(deltas) - self._limits.keys()
        if unknown:
            raise KeyError(f"not DOF agents of {self.topo.name!r}: {sorted(unknown)}")
        q = dict(self._q)
        applied = dict.fromkeys(self._dof, 0.0)
        for a, d in deltas.items():
            d = float(d)
            if not math.isfinite(d):
                raise ValueError(f"increment for {a!r} is not finite: {d}")
            lo, hi = self._limits[a]
            new = min(max(q[a] + d, lo), hi)
            applied[a] = new - q[a]
            q[a] = new
        self._write(q)
        return applied

    def tip_poses(self) -> dict[str, Pose]:
        """Every end effector's pose from PyBullet's link frames ([4], [5]): a planar robot's (x, y, heading), the
        heading from a quaternion, so wrapped to (-pi, pi]; a spatial robot's 7-float frame (protocol/frames.py)."""
        states = pb.getLinkStates(self.body, self._tip_idx, computeForwardKinematics=1, physicsClientId=self.client)
        out: dict[str, Pose] = {}
        if self._tools is not None:
            for leaf, st, tool in zip(self._leaves, states, self._tools, strict=True):
                out[leaf] = frames.compose((*st[4], *st[5]), tool)
            return out
        for leaf, st in zip(self._leaves, states, strict=True):
            (x, y, _), (qx, qy, qz, qw) = st[4], st[5]
            out[leaf] = (x, y, math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz)))
        return out

    def close(self) -> None:
        if not self._owner:  # its robot goes with the client's owner
            self.client = -1
            return
        if self.client >= 0:
            pb.disconnect(physicsClientId=self.client)
            self.client = -1
        if self._tmpdir is not None:
            shutil.rmtree(self._tmpdir, ignore_errors=True)
            self._tmpdir = None
        elif getattr(self, "_written", None) is not None:
            self._written.unlink(missing_ok=True)

    def __enter__(self) -> World:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()
