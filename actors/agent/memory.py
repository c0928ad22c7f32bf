"""An agent's learned state across processes: a checkpoint on the supervisor's request, a start from another run's
checkpoints (`--from`), and a restart's resume from this run's newest good one (actors/files/checkpoint.py: the
files)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from kinswarm.actors.files.checkpoint import CheckpointError, digest, load_latest, save_checkpoint
from kinswarm.actors.policies.registry import DEFAULT
from kinswarm.actors.step.learned import checkpoint_meta, learned_state, load_learned, restore_learner
from kinswarm.protocol.messages import Checkpoint, Event, Saved

if TYPE_CHECKING:
    from .actor import Agent


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
            except OSError as e:  # a full disk, a read-only directory: the line the run fails with
                error = f"cannot write {path}: {e.strerror or e}"
                a.node.log.error(error)
        self.saved = Saved(epoch=m.epoch, path=str(path), error=error)
        a.node.send(a.keys.rep("agent", a.id), self.saved)
