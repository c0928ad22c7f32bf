"""A learner's learned state as a checkpoint holds it: the arrays and where its random generator is
(`learned_state`, `load_learned`), what the checkpoint records beside them (`checkpoint_meta`), and another run's
checkpoint loaded as a start (`restore_learner`). The files themselves: actors/files/checkpoint.py. The agent actor
(actors/agent/memory.py) and the inprocess loop write and read checkpoints through these, so they are the same."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
from kinswarm.actors.files.checkpoint import load_checkpoint


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
