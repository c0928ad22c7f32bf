"""The resolved run written back as a run file (`<run>/run.toml`): `kinswarm run` of it makes the same run again, the
learner's settings as they were used."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import tomli_w
from kinswarm.actors.files.config import RUN_KEYS, RunConfig
from kinswarm.actors.files.runfile import learner_settings, task_of
from kinswarm.actors.files.tables import plain
from kinswarm.actors.learning.settings import LearnerSettings
from kinswarm.actors.tasks.base import TaskDef
from kinswarm.protocol.spec import SpecError


def write_resolved(cfg: RunConfig, path: Path) -> Path:
    """The resolved run as a run file: `kinswarm run` of it makes the same run again (in a new directory), with the
    learner's settings as they were used (resolved_learner), so a change of a default in the code changes no run
    made from it."""
    run = {k: getattr(cfg, "from_dir" if k == "from" else k) for k in RUN_KEYS}
    learner = resolved_learner(task_of(cfg), cfg.learner, cfg.source) if cfg.controller == "agents" else cfg.learner
    doc = {
        "run": {k: v for k, v in run.items() if v is not None},
        "robot": cfg.robot,
        "scene": cfg.scene,
        "task": cfg.task,
        "learner": learner,
    }
    header = f"# The resolved run {cfg.run_id} (from {cfg.source}): `kinswarm run` this file to make it again.\n"
    path.write_text(header + tomli_w.dumps(plain(doc)))
    return path


def resolved_learner(task: TaskDef, learner: Mapping[str, Any], source: str = "<memory>") -> dict[str, Any]:
    """The [learner] table that gives every agent the settings `learner` gives it now, with every setting written
    out that one value can say for all: what the code's defaults gave is then in the file, not in the code. A
    setting the task makes per agent (ranges over each joint's own limits) or adds to (its state variables, which
    it puts before those of [learner]) stays the task's: written out, it would change the run."""
    used = learner_settings(task, learner, source)
    if not used:
        return dict(learner)
    first = next(iter(used.values()))
    candidates = {  # one value for every agent, and not given
        f.name: plain(getattr(first, f.name))
        for f in dataclasses.fields(LearnerSettings)
        if f.name not in learner and all(getattr(s, f.name) == getattr(first, f.name) for s in used.values())
    }

    def same(extra: Mapping[str, Any]) -> bool:
        try:
            return learner_settings(task, {**learner, **extra}, source) == used
        except (SpecError, ValueError):  # the task's variables twice, say: not a setting it takes as written
            return False

    # all of them; or all but one (a task's own variables); or one by one. Settings that hang together (a spatial
    # joint's state, its sets and their ranges) are only taken together.
    tries = [candidates, *({k: v for k, v in candidates.items() if k != name} for name in candidates)]
    for extra in tries:
        if same(extra):
            return {**learner, **extra}
    out: dict[str, Any] = {}
    for name, value in candidates.items():
        if same({**out, name: value}):
            out[name] = value
    return {**learner, **out}
