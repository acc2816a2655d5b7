"""MJX Sawyer scenes and a pure-JAX camera renderer (the Env contract of docs/architecture.md)."""

import functools

from envs_mjx.env import Env, EnvState, LABEL_BACKGROUND, LABEL_OBJECT, LABEL_ROBOT
from envs_mjx.tasks import TASKS
from envs_mjx import registry

TASK_NAMES = tuple(TASKS)


def make(name: str) -> Env:
    """A task's Env: one of TASK_NAMES. One instance per task and process (an Env is
    immutable), so programs jitted per env (the training chunk, data collection) are traced
    and compiled once however many runs the process makes."""
    if name not in TASKS:
        raise ValueError(f"unknown task {name!r}; expected one of {', '.join(TASK_NAMES)}")
    return _make(name)


@functools.lru_cache(maxsize=None)
def _make(name: str) -> Env:
    return Env(TASKS[name])


# The Gymnasium ids roll/PuckPush-v0, ... (docs/environments.md): registered here when
# gymnasium is installed; their entry points are strings, resolved by gymnasium.make.
registry.register_gymnasium()

__all__ = ["Env", "EnvState", "TASK_NAMES", "TASKS", "make",
           "LABEL_BACKGROUND", "LABEL_ROBOT", "LABEL_OBJECT", "registry"]
