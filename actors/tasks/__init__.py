"""Tasks: one module per task, each holding a `TaskDef` subclass named `TASK` (base.py is the interface).

A task's kind is its module's name; the run file declares it (`[task] kind = "reach"`), nothing infers it. Adding a
task is adding a module here and an example run file (docs/tasks.md).
"""

from __future__ import annotations

import importlib
import pkgutil
from functools import cache

from .base import AgentTask, Head, StepView, TaskDef

_NOT_TASKS = frozenset({"base", "grasp_reward"})


@cache
def kinds() -> tuple[str, ...]:
    """Every task kind: the modules of this package that define TASK."""
    names = sorted(m.name for m in pkgutil.iter_modules(__path__) if m.name not in _NOT_TASKS)
    return tuple(n for n in names if hasattr(importlib.import_module(f"{__name__}.{n}"), "TASK"))


def task_class(kind: str) -> type[TaskDef]:
    if kind not in kinds():
        raise ValueError(f"unknown task kind {kind!r}; expected one of {', '.join(kinds())}")
    return importlib.import_module(f"{__name__}.{kind}").TASK


__all__ = ["AgentTask", "Head", "StepView", "TaskDef", "kinds", "task_class"]
