"""The five tasks by name, Playground style (`load(name, **config)`, `ALL_ENVS`), and their
Gymnasium ids (`roll/PuckPush-v0`, ...; registered by `import envs_mjx`).

This module imports nothing heavy: `load` imports `envs_mjx.standard` when first called, and
the Gymnasium entry points are strings that `gymnasium.make` resolves to `envs_mjx.gym`.
"""

from __future__ import annotations

import functools
from typing import Any, Mapping

# Playground-style names -> the task names of envs_mjx.TASKS.
TASK_OF = {
    "PuckPush": "puck_push",
    "HurdleBottom": "hurdle_bottom",
    "HurdleTop": "hurdle_top",
    "DoorOpen": "door_open",
    "Pickup": "pickup",
}
ALL_ENVS = tuple(TASK_OF)
NAME_OF = {task: name for name, task in TASK_OF.items()}
GYM_NAMESPACE = "roll"
GYM_IDS = tuple(f"{GYM_NAMESPACE}/{name}-v0" for name in ALL_ENVS)


def task_name(name: str) -> str:
    """A Playground name ("PuckPush") or a task name ("puck_push") -> the task name."""
    if name in TASK_OF:
        return TASK_OF[name]
    if name in NAME_OF:
        return name
    raise ValueError(f"unknown environment {name!r}; expected one of {', '.join(ALL_ENVS)} "
                     f"(or a task name: {', '.join(NAME_OF)})")


def get_default_config(name: str):
    """The default `envs_mjx.standard.Config` of an environment (its ctrl_dt is the task's)."""
    from envs_mjx.standard import make_config

    return make_config(task=task_name(name))


def load(name: str, config=None, config_overrides: Mapping[str, Any] | None = None,
         **overrides):
    """The Playground-style env of a task: `load("PuckPush", obs_type="state")`. `config`
    (a Config or a mapping), `config_overrides` and keyword overrides are merged in that
    order. One instance per task and config, so programs jitted on it (`env.jit_step`) are
    compiled once per process."""
    import dataclasses

    task = task_name(name)
    from envs_mjx.standard import Config, make_config

    merged: dict[str, Any] = {}
    if isinstance(config, Config):
        merged.update(dataclasses.asdict(config))
    elif config is not None:
        merged.update(dict(config))
    merged.update(config_overrides or {})
    merged.update(overrides)
    cfg = make_config(merged, task=task)
    return _load(task, cfg)


@functools.lru_cache(maxsize=None)
def _load(task: str, cfg):
    import envs_mjx
    from envs_mjx.standard import RollEnv

    return RollEnv(envs_mjx.make(task), cfg)


def register_gymnasium() -> bool:
    """Register the five ids with Gymnasium when it is installed (idempotent). Returns
    whether Gymnasium is there."""
    try:
        import gymnasium
    except ImportError:
        return False
    for name, gym_id in zip(ALL_ENVS, GYM_IDS):
        if gym_id in gymnasium.registry:
            continue
        gymnasium.register(
            id=gym_id,
            entry_point="envs_mjx.gym:RollGoalEnv",
            vector_entry_point="envs_mjx.gym:RollGoalVectorEnv",
            kwargs={"task": TASK_OF[name]},
            nondeterministic=False,
        )
    return True
