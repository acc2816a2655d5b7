"""MJX Sawyer scenes and a pure-JAX camera renderer (the Env contract of docs/architecture.md)."""

from envs_mjx.env import Env, EnvState, LABEL_BACKGROUND, LABEL_OBJECT, LABEL_ROBOT
from envs_mjx.tasks import TASKS

TASK_NAMES = tuple(TASKS)


def make(name: str) -> Env:
    """Build a task's Env: one of TASK_NAMES."""
    if name not in TASKS:
        raise ValueError(f"unknown task {name!r}; expected one of {', '.join(TASK_NAMES)}")
    return Env(TASKS[name])


__all__ = ["Env", "EnvState", "TASK_NAMES", "TASKS", "make",
           "LABEL_BACKGROUND", "LABEL_ROBOT", "LABEL_OBJECT"]
