"""The five scenes as MuJoCo Playground-style environments (docs/environments.md).

`RollEnv(task, config)` follows `mujoco_playground.MjxEnv`'s contract: pure
`reset(rng) -> State` and `step(state, action) -> State`, where `State` carries `data` (the
`mjx.Data`), `obs`, `reward`, `done`, `metrics` and `info`; `observation_size`,
`action_size`, `mj_model`, `mjx_model`, `dt`. Every episode draws its goal with
`Env.sample_goal`; the reward is minus the paper's metric (`Env.goal_distance`: the object's
position error in metres, the door's angle error in radians); `done` is 1 at the horizon.

When the optional `playground` package is installed (`pip install -e ".[playground]"`)
`RollEnv` subclasses its `MjxEnv` and returns its `State`, so its wrappers
(`wrap_for_brax_training`) and Brax's trainers take the env as they take Playground's own;
otherwise a local base class with the same contract stands in (no brax or warp-lang needed).
Build one with `envs_mjx.registry.load(name, **config)`.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Mapping

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from envs_mjx import scenes
from envs_mjx.env import Env, mjx

OBS_TYPES = ("pixels", "state")

try:  # optional: MuJoCo Playground's base class and State (pulls brax and warp-lang)
    from ml_collections import config_dict as _config_dict
    from mujoco_playground import MjxEnv as _PlaygroundMjxEnv
    from mujoco_playground import State as _PlaygroundState

    HAVE_PLAYGROUND = True
except ImportError:
    HAVE_PLAYGROUND = False


if HAVE_PLAYGROUND:
    State = _PlaygroundState
    _Base = _PlaygroundMjxEnv
else:
    @struct.dataclass
    class State:
        """Environment state for training and inference (mujoco_playground's `State`)."""

        data: mjx.Data
        obs: Any
        reward: jax.Array
        done: jax.Array
        metrics: dict[str, jax.Array]
        info: dict[str, Any]

        def tree_replace(self, params: Mapping[str, Any]) -> "State":
            """`state.tree_replace({"info.t": x})`: replace a nested field by its dotted path."""
            new = self
            for path, value in params.items():
                new = _tree_replace(new, path.split("."), value)
            return new

    class _Base:
        """The part of `mujoco_playground.MjxEnv` a trainer relies on, without its imports."""

        def __init__(self, config, config_overrides=None):
            self._config = config
            self._ctrl_dt = config.ctrl_dt
            self._sim_dt = config.sim_dt

        @property
        def dt(self) -> float:
            """Control timestep (s)."""
            return self._ctrl_dt

        @property
        def sim_dt(self) -> float:
            """Simulation timestep (s)."""
            return self._sim_dt

        @property
        def n_substeps(self) -> int:
            return int(round(self.dt / self.sim_dt))

        @property
        def unwrapped(self):
            return self


def _tree_replace(base, attr, value):
    if len(attr) == 1:
        if isinstance(base, dict):
            return {**base, attr[0]: value}
        return base.replace(**{attr[0]: value})
    child = base[attr[0]] if isinstance(base, dict) else getattr(base, attr[0])
    new = _tree_replace(child, attr[1:], value)
    if isinstance(base, dict):
        return {**base, attr[0]: new}
    return base.replace(**{attr[0]: new})


@dataclasses.dataclass(frozen=True)
class Config:
    """What a `RollEnv` can be configured with (`registry.load(name, **fields)`)."""

    obs_type: str = "pixels"  # "pixels": the camera image; "state": hand xyz + object state
    goal_in_obs: bool = True  # append the goal (image channels / object state) to obs
    image_size: int = 48  # pixels: square render size
    episode_length: int | None = None  # None: the task's horizon (50; door_open 100)
    done_at_horizon: bool = True  # False: never done (a wrapper such as Brax's truncates)
    # Fixed by the scene: None, or the task's n_substeps x TIMESTEP (0.1 s; door_open 0.15 s).
    ctrl_dt: float | None = None
    sim_dt: float = scenes.TIMESTEP  # fixed by the scene


CONFIG_FIELDS = tuple(f.name for f in dataclasses.fields(Config))


def task_ctrl_dt(task: str) -> float:
    """Seconds per env step of `task`: its n_substeps x scenes.TIMESTEP."""
    from envs_mjx.tasks import TASKS

    return TASKS[task].n_substeps * scenes.TIMESTEP


def make_config(overrides: Mapping[str, Any] | None = None, task: str | None = None) -> Config:
    """A checked Config: an unknown field, a wrong obs_type or size names the value and the
    valid choices. With `task`, ctrl_dt becomes the task's (a different one is refused)."""
    overrides = dict(overrides or {})
    unknown = sorted(set(overrides) - set(CONFIG_FIELDS))
    if unknown:
        raise ValueError(f"unknown env config field(s) {', '.join(map(repr, unknown))}; "
                         f"valid fields: {', '.join(CONFIG_FIELDS)}")
    cfg = Config(**overrides)
    if cfg.obs_type not in OBS_TYPES:
        raise ValueError(f"unknown obs_type {cfg.obs_type!r}; expected one of "
                         f"{', '.join(map(repr, OBS_TYPES))}")
    if not isinstance(cfg.image_size, (int, np.integer)) or cfg.image_size <= 0:
        raise ValueError(f"image_size must be a positive int, got {cfg.image_size!r}")
    if cfg.episode_length is not None and (
            not isinstance(cfg.episode_length, (int, np.integer)) or cfg.episode_length <= 0):
        raise ValueError(f"episode_length must be a positive int or None, got "
                         f"{cfg.episode_length!r}")
    if not math.isclose(cfg.sim_dt, scenes.TIMESTEP):
        raise ValueError(f"sim_dt is fixed by the scene ({scenes.TIMESTEP}), got {cfg.sim_dt!r}")
    if task is None:
        return cfg
    dt = task_ctrl_dt(task)
    if cfg.ctrl_dt is not None and not math.isclose(cfg.ctrl_dt, dt):
        raise ValueError(f"ctrl_dt is fixed by the scene of {task!r} ({dt:g}), got "
                         f"{cfg.ctrl_dt!r}")
    return dataclasses.replace(cfg, ctrl_dt=dt)


class RollEnv(_Base):
    """One ROLL task as a Playground-style environment. Pure `reset` / `step`: jit and vmap
    them (`jax.jit(jax.vmap(env.step))`)."""

    def __init__(self, base: Env, config: Config | Mapping[str, Any] | None = None):
        if isinstance(config, Config):
            config = dataclasses.asdict(config)
        config = make_config(config, task=base.name)
        self.config = config
        if HAVE_PLAYGROUND:
            super().__init__(_config_dict.ConfigDict(dataclasses.asdict(config)))
        else:
            super().__init__(config)
        self.base = base
        self.task = base.name
        self.obs_type = config.obs_type
        self.goal_in_obs = bool(config.goal_in_obs)
        self.image_size = int(config.image_size)
        self.episode_length = int(config.episode_length or base.horizon)
        self.horizon = base.horizon
        self.goal_size = base.object_size  # length of the goal / object state

    # ------------------------------------------------------------ Playground properties
    @property
    def action_size(self) -> int:
        return self.base.action_size

    @property
    def mj_model(self):
        return self.base.mj_model

    @property
    def mjx_model(self):
        return self.base.mjx_model

    @property
    def xml_path(self) -> str:
        """The scenes are generated (`envs_mjx.scenes.scene_xml`), not read from a file; the
        XML itself is `env.xml`."""
        return f"envs_mjx.scenes.scene_xml({self.task!r})"

    @property
    def xml(self) -> str:
        return self.base.xml

    @property
    def proprio_size(self) -> int:
        """Length of the state observation before the object: hand xyz (+ 2 finger joints on
        pickup)."""
        return 3 + (2 if self.base.kind == "pickup" else 0)

    @property
    def observation_size(self) -> int | tuple[int, int, int]:
        """state: the vector's length; pixels: (height, width, channels), channels 6 with the
        goal image stacked after the current one, else 3."""
        if self.obs_type == "state":
            return self.proprio_size + self.goal_size * (2 if self.goal_in_obs else 1)
        return (self.image_size, self.image_size, 6 if self.goal_in_obs else 3)

    # ------------------------------------------------------------ readouts
    def achieved_goal(self, data) -> jax.Array:
        """float32[k]: the object state (puck xy, door angle, object xyz) of `data`."""
        a = self.base.object_qadr
        return data.qpos[a:a + self.goal_size]

    def goal_distance(self, achieved, goal) -> jax.Array:
        """The paper's metric between object states [..., k] -> [...]."""
        return self.base.object_distance(achieved, goal)

    def _image(self, data) -> jax.Array:
        s = self.image_size
        return self.base.renderer(s, s).render(data.geom_xpos, data.geom_xmat)[0]

    def _obs(self, data, info) -> jax.Array:
        if self.obs_type == "pixels":
            img = self._image(data)
            if self.goal_in_obs:
                return jnp.concatenate([img, info["goal_image"]], axis=-1)
            return img
        parts = [data.xpos[self.base._hand_body]]
        if self.base.kind == "pickup":
            parts.append(data.qpos[np.asarray(self.base._finger_qadr)])
        parts.append(self.achieved_goal(data))
        if self.goal_in_obs:
            parts.append(info["goal"])
        return jnp.concatenate([jnp.asarray(p, jnp.float32) for p in parts])

    # ------------------------------------------------------------ contract
    def reset(self, rng: jax.Array) -> State:
        """A full reset (also on door_open, whose training loop is reset-free) and a goal
        drawn from the task's goal space."""
        k_reset, k_goal = jax.random.split(rng)
        start = self.base.reset(k_reset)
        goal_state = self.base.sample_goal(k_goal)
        goal = self.achieved_goal(goal_state.data)
        info = {"goal": goal, "t": jnp.zeros((), jnp.int32),
                "truncation": jnp.zeros((), jnp.float32)}
        if self.obs_type == "pixels":
            info["goal_image"] = self._image(goal_state.data)
        dist = self.goal_distance(self.achieved_goal(start.data), goal)
        return State(data=start.data, obs=self._obs(start.data, info),
                     reward=jnp.zeros((), jnp.float32), done=jnp.zeros((), jnp.float32),
                     metrics={"goal_distance": dist,
                              "final_goal_distance": jnp.zeros((), jnp.float32)}, info=info)

    def step(self, state: State, action: jax.Array) -> State:
        """One control step (0.1 s: the mocap moves by 0.02 * clip(action, -1, 1), then 10
        physics substeps); reward -goal_distance after it; done at the episode length."""
        t = state.info["t"]
        nxt = self.base.step(self.base_state(state), action)
        t = t + 1
        info = {**state.info, "t": t}
        dist = self.goal_distance(self.achieved_goal(nxt.data), info["goal"])
        at_end = (t >= self.episode_length).astype(jnp.float32)
        if self.config.done_at_horizon:
            done = at_end
            info["truncation"] = at_end
        else:
            done = jnp.zeros((), jnp.float32)
            info["truncation"] = jnp.zeros((), jnp.float32)
        # the distance at the episode's last step, 0 before: its sum over an episode (what
        # Brax's evaluator reports) is the paper's final distance
        final = jnp.where(t == self.episode_length, dist, 0.0).astype(jnp.float32)
        metrics = {**state.metrics, "goal_distance": dist, "final_goal_distance": final}
        return state.replace(data=nxt.data, obs=self._obs(nxt.data, info),
                             reward=-dist.astype(jnp.float32), done=done, metrics=metrics,
                             info=info)

    def base_state(self, state: State):
        """The `envs_mjx.Env` state (data, step count) of a State, for `env.base`'s methods."""
        from envs_mjx.env import EnvState

        return EnvState(data=state.data, t=state.info["t"])

    def render(self, trajectory, height: int = 48, width: int = 48, camera=None, **_):
        """uint8[height, width, 3] images of a State or a list of States, from the task's
        camera by the JAX ray caster (Playground's `render` draws with OpenGL)."""
        if camera is not None:
            raise ValueError(f"task {self.task!r} has one camera; got camera={camera!r}")
        states = trajectory if isinstance(trajectory, (list, tuple)) else [trajectory]
        fn = _render_fn(self.base, int(width), int(height))
        frames = [np.asarray(fn(s.data.geom_xpos, s.data.geom_xmat)) for s in states]
        return frames if isinstance(trajectory, (list, tuple)) else frames[0]

    # ------------------------------------------------------------ compiled, shared
    def _jitted(self, name, fn):
        if name not in self.__dict__:
            self.__dict__[name] = jax.jit(fn)
        return self.__dict__[name]

    @property
    def jit_reset(self):
        """`jax.jit(env.reset)`, built once per env (the Gymnasium envs use these four)."""
        return self._jitted("_jit_reset", self.reset)

    @property
    def jit_step(self):
        """`jax.jit(env.step)`."""
        return self._jitted("_jit_step", self.step)

    @property
    def jit_vreset(self):
        """`jax.jit(jax.vmap(env.reset))`: keys [N, 2] -> a State with a leading N axis."""
        return self._jitted("_jit_vreset", jax.vmap(self.reset))

    @property
    def jit_vstep(self):
        """`jax.jit(jax.vmap(env.step))`: every env of a batch in one call."""
        return self._jitted("_jit_vstep", jax.vmap(self.step))

    def __repr__(self) -> str:
        return (f"RollEnv({self.task!r}, obs_type={self.obs_type!r}, "
                f"goal_in_obs={self.goal_in_obs}, episode_length={self.episode_length})")


_RENDER_FNS: dict = {}


def _render_fn(base: Env, width: int, height: int):
    key = (id(base), width, height)
    if key not in _RENDER_FNS:
        renderer = base.renderer(width, height)
        _RENDER_FNS[key] = jax.jit(lambda xpos, xmat: renderer.render(xpos, xmat)[0])
    return _RENDER_FNS[key]
