"""An agent's learned state across processes: a checkpoint on the supervisor's request, a start from another run's
checkpoints (`--from`), and a restart's resume from this run's newest good one (actors/run/checkpoint.py: the files)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from kinswarm.actors.learning.kinds import DEFAULT
from kinswarm.actors.run.checkpoint import CheckpointError, digest, load_checkpoint, load_latest, save_checkpoint
from kinswarm.protocol.messages import Checkpoint, Event, Saved

if TYPE_CHECKING:
    from .actor import Agent


def checkpoint_meta(agent: str, kind: str, topology: str, epochs_before: int, epoch: int, seed: int) -> dict:
    """What a checkpoint records beside the learned arrays (`kind`: the learner kind whose state they are)."""
    return {
        "agent": agent,
        "learner": kind,
        "topology": topology,
        "epochs_trained": epochs_before + epoch + 1,
        "epochs_before": epochs_before,
        "run_epoch": epoch,
        "seed": seed,
    }


RNG = "rng_state"  # a checkpoint's array of the learner's random generator (JSON bytes of its bit generator's state)


def learned_state(learner: Any) -> dict[str, np.ndarray]:
    """What a checkpoint holds of a learner: its state dict and where its random generator is, so a run resumed from
    it draws what the run would have drawn (a restart's exploration goes on as it would have, too). A learner that
    draws nothing (a frozen policy: no `rng`) has its state dict alone."""
    if not hasattr(learner, "rng"):
        return learner.state_dict()
    rng = json.dumps(learner.rng.bit_generator.state).encode()
    return {**learner.state_dict(), RNG: np.frombuffer(rng, dtype=np.uint8)}


def load_learned(learner: Any, arrays: dict[str, np.ndarray]) -> None:
    """`learned_state` back into a learner (a checkpoint without the generator's state leaves it as it is)."""
    learner.load_state_dict(arrays)
    if RNG in arrays:
        try:
            learner.rng.bit_generator.state = json.loads(arrays[RNG].tobytes().decode())
        except (ValueError, TypeError, KeyError) as e:  # the digest matched: written so by a kinswarm that differs
            raise ValueError(f"rng_state: not this learner's random generator's state ({e})") from None


def restore_learner(learner: Any, path: Path, agent: str, kind: str) -> int:
    """A previous run's checkpoint into `learner` of `kind` (`--from`): the epochs it was trained, for the lr
    schedule."""
    arrays, meta = load_checkpoint(path, agent=agent, learner=kind)
    learner.load_state_dict(arrays)  # another run's: its knowledge, not its random draws
    return int(meta.get("epochs_trained", 0))


class Memory:
    def __init__(self, agent: Agent) -> None:
        self.agent = agent
        self.epochs_before = 0  # epochs trained before this run (from --from), for the lr schedule
        self.restored: Event | None = None  # what a restart restored, announced once alive
        self.kind: str = agent.cfg.learner.get("kind", DEFAULT)  # the learner kind its checkpoints hold the state of
        self.saved: Saved | None = None  # the answer to the last checkpoint request, given again if it comes again

    def restore(self, directory: Path) -> None:
        """Start from a previous run's checkpoint (`--from`)."""
        a = self.agent
        if a.learner is None:
            return
        self.epochs_before = restore_learner(a.learner, directory / f"{a.id}.npz", a.id, self.kind)

    def resume(self, directory: Path) -> None:
        """A restart: the learned state of this run's newest good checkpoint (else the one before it);
        before the first checkpoint, the run's starting point (`--from`, or fresh)."""
        a = self.agent
        if a.learner is None:
            self.restored = Event(epoch=-1, step=-1, event="restored", target=a.id, detail="no learned state")
            return
        try:
            arrays, meta, used, refused = load_latest(directory / f"{a.id}.npz", agent=a.id, learner=self.kind)
        except CheckpointError as e:
            if a.cfg.from_dir:
                self.restore(Path(a.cfg.from_dir) / "agents")
            detail = f"no good checkpoint of this run ({e}); starting from {a.cfg.from_dir or 'scratch'}"
            a.node.log.warning(detail)
            self.restored = Event(epoch=-1, step=-1, event="restored", target=a.id, detail=detail)
            return
        for reason in refused:
            a.node.log.warning("checkpoint refused: %s", reason)
        load_learned(a.learner, arrays)
        self.epochs_before = int(meta.get("epochs_before", 0))
        detail = (
            f"{used.name} of epoch {meta.get('run_epoch')}: checkpoint sha256={meta['sha256']} "
            f"restored sha256={digest(learned_state(a.learner))}"
        )
        if refused:
            detail += f"; refused: {'; '.join(refused)}"
        epoch = int(meta.get("run_epoch", -1))
        self.restored = Event(epoch=epoch, step=-1, event="restored", target=a.id, detail=detail)

    def save(self, m: Checkpoint) -> None:
        # Into this agent's own run directory, where a restart restores from: on another host than the
        # leader's, `m.directory` (the leader's) need not exist.
        a = self.agent
        if self.saved is not None and m.epoch <= self.saved.epoch:  # asked again: its answer was lost on the way
            if m.epoch == self.saved.epoch:  # (an older request is stale: saving now would label this state wrong)
                a.node.send(a.keys.rep("agent", a.id), self.saved)
            return
        path = Path(a.cfg.out) / "agents" / f"{a.id}.npz"
        error = ""
        if a.learner is not None:
            try:
                meta = checkpoint_meta(a.id, self.kind, a.topo.name, self.epochs_before, m.epoch, a.cfg.seed)
                save_checkpoint(path, learned_state(a.learner), meta)
            except OSError as e:
                error = f"cannot write {path}: {e}"
                a.node.log.error(error)
        self.saved = Saved(epoch=m.epoch, path=str(path), error=error)
        a.node.send(a.keys.rep("agent", a.id), self.saved)
