"""Gymnasium environments of the five scenes (docs/environments.md).

`gymnasium.make("roll/PuckPush-v0", obs_type="pixels"|"state")` gives a `RollGoalEnv`:
goal-conditioned `Dict` observations `observation` / `achieved_goal` / `desired_goal` as
Gymnasium-Robotics has them, `compute_reward(achieved_goal, desired_goal, info)` vectorised,
`render_mode="rgb_array"`, seeding by `reset(seed=...)`, truncation at the horizon.
`gymnasium.make_vec(id, num_envs=N)` gives a `RollGoalVectorEnv` that steps all N envs in one
jitted, vmapped call and resets finished ones on the next step (Gymnasium's next-step
autoreset). Both run the Playground-style `envs_mjx.standard.RollEnv` underneath; its compiled
programs are shared by every env of the same task and config in the process.
"""

from __future__ import annotations

from typing import Any

import gymnasium
import jax
import jax.numpy as jnp
import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from envs_mjx import registry
from envs_mjx.standard import OBS_TYPES, RollEnv, _render_fn

RENDER_MODES = ("rgb_array",)
_SEED_HIGH = 2**31 - 1
# State observations and goals are positions in metres and the door's angle in radians; the
# scenes keep them well inside this box.
STATE_BOUND = 2.0


def _check_render_mode(render_mode):
    if render_mode is not None and render_mode not in RENDER_MODES:
        raise ValueError(f"unknown render_mode {render_mode!r}; expected None or one of "
                         f"{', '.join(map(repr, RENDER_MODES))}")


def _load(task: str, obs_type: str, config: dict[str, Any]) -> RollEnv:
    if obs_type not in OBS_TYPES:
        raise ValueError(f"unknown obs_type {obs_type!r}; expected one of "
                         f"{', '.join(map(repr, OBS_TYPES))}")
    if "goal_in_obs" in config:
        raise ValueError("goal_in_obs is not an option of the Gymnasium envs: the goal is "
                         "always the 'desired_goal' entry of the observation")
    return registry.load(task, obs_type=obs_type, **config)


def goal_spaces(env: RollEnv) -> spaces.Dict:
    """The Dict observation space of one env."""
    if env.obs_type == "pixels":
        s = env.image_size
        image = spaces.Box(0, 255, (s, s, 3), np.uint8)
        return spaces.Dict({"observation": image, "achieved_goal": image,
                            "desired_goal": image})
    k = env.goal_size

    def box(n):
        return spaces.Box(-STATE_BOUND, STATE_BOUND, (n,), np.float32)

    return spaces.Dict({"observation": box(env.proprio_size + k), "achieved_goal": box(k),
                        "desired_goal": box(k)})


def _split_obs(env: RollEnv, obs, goal, goal_image) -> dict[str, np.ndarray]:
    """RollEnv observations (leading batch axes allowed) -> the Dict observation, new arrays."""
    if env.obs_type == "pixels":
        current = np.array(obs[..., :3])
        return {"observation": current, "achieved_goal": current.copy(),
                "desired_goal": np.array(goal_image)}
    p, k = env.proprio_size, env.goal_size
    return {"observation": np.array(obs[..., :p + k]),
            "achieved_goal": np.array(obs[..., p:p + k]), "desired_goal": np.array(goal)}


def _object_of(env: RollEnv, qpos) -> np.ndarray:
    """The object state (a new float32 array) from qpos [..., nq] on the host."""
    a = env.base.object_qadr
    return np.array(qpos[..., a:a + env.goal_size], np.float32)


def _object_distance(kind: str, achieved, desired) -> np.ndarray:
    diff = np.asarray(achieved, np.float32) - np.asarray(desired, np.float32)
    if kind == "door":
        return np.abs(diff[..., 0])
    return np.linalg.norm(diff, axis=-1)


def _info_objects(info, key):
    """info[key] from one info dict, a vector env's info dict, or a sequence of info dicts."""
    if isinstance(info, dict):
        return np.asarray(info[key], np.float32)
    return np.stack([np.asarray(i[key], np.float32) for i in info])



def _rgb_frames(env):
    """The camera image(s) of a Gymnasium env's state ([H, W, 3], or [N, H, W, 3] for the
    vector env), or None (with Gymnasium's warning) without a render mode."""
    if env.render_mode is None:
        gymnasium.logger.warn("render() called without a render_mode; make the env with "
                              "render_mode='rgb_array'")
        return None
    if env._state is None:
        raise gymnasium.error.ResetNeeded("call reset() before render()")
    if env.obs_type == "pixels":
        return np.array(jax.device_get(env._state.obs[..., :3]))
    s = env._env.image_size
    fn = _render_fn(env._env.base, s, s)
    d = env._state.data
    if d.geom_xpos.ndim == 2:  # one env
        return np.array(fn(d.geom_xpos, d.geom_xmat))
    return np.stack([np.asarray(fn(x, m)) for x, m in zip(d.geom_xpos, d.geom_xmat)])


def _checked_actions(env, actions, what: str) -> np.ndarray:
    """float32 actions of `env`'s action space; ResetNeeded before the first reset, and a
    ValueError naming the task for a wrong shape or a non-finite value."""
    if env._state is None:
        raise gymnasium.error.ResetNeeded("call reset() before step()")
    a = np.asarray(actions, np.float32)
    if a.shape != env.action_space.shape:
        raise ValueError(f"{what} for {env.task!r} must have shape {env.action_space.shape}, "
                         f"got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{what} for {env.task!r} is not finite: {a}")
    return a

class _GoalReward:
    """`compute_reward` shared by the single and the vector env."""

    _env: RollEnv

    def compute_reward(self, achieved_goal, desired_goal, info) -> np.ndarray:
        """Minus the paper's metric, vectorised over leading axes (Gymnasium-Robotics'
        signature, for HER relabelling). State goals are object states: the distance between
        them. Pixel goals are images: the distance between the object states that `info`
        records for them ('achieved_object' and 'desired_object'; an info dict, a vector
        env's info, or a sequence of info dicts), since an image does not give its object's
        position."""
        kind = self._env.base.kind
        if self._env.obs_type == "state":
            return -_object_distance(kind, achieved_goal, desired_goal)
        try:
            achieved = _info_objects(info, "achieved_object")
            desired = _info_objects(info, "desired_object")
        except (KeyError, TypeError) as e:
            raise ValueError(
                "compute_reward on pixel goals needs the object states in info "
                "('achieved_object', 'desired_object', as step() returns them); an image does "
                "not give the object's position") from e
        return -_object_distance(kind, achieved, desired)


class RollGoalEnv(_GoalReward, gymnasium.Env):
    """One task as a goal-conditioned Gymnasium env. `task`: a task name (puck_push,
    hurdle_bottom, hurdle_top, door_open, pickup) or a Playground name (PuckPush, ...);
    `obs_type`: "pixels" (48x48 uint8 images) or "state"; further keywords are
    `envs_mjx.standard.Config` fields (image_size, episode_length)."""

    metadata = {"render_modes": list(RENDER_MODES), "render_fps": 10}

    def __init__(self, task: str = "puck_push", obs_type: str = "pixels",
                 render_mode: str | None = None, **config):
        _check_render_mode(render_mode)
        self._env = _load(task, obs_type, config)
        self.task = self._env.task
        # real time: 10 frames per second, the door's 0.15 s steps 6.67
        self.metadata = {**self.metadata, "render_fps": 1.0 / self._env.dt}
        self.obs_type = obs_type
        self.render_mode = render_mode
        self.observation_space = goal_spaces(self._env)
        self.action_space = spaces.Box(-1.0, 1.0, (self._env.action_size,), np.float32)
        self._state = None

    @property
    def roll_env(self) -> RollEnv:
        """The Playground-style env underneath (pure reset/step for jit and vmap)."""
        return self._env

    def _observe(self):
        s = self._state
        obs, goal, goal_image, dist, qpos, t = jax.device_get((
            s.obs, s.info["goal"], s.info.get("goal_image"), s.metrics["goal_distance"],
            s.data.qpos, s.info["t"]))
        ob = _split_obs(self._env, obs, goal, goal_image)
        info = {"goal_distance": float(dist), "achieved_object": _object_of(self._env, qpos),
                "desired_object": np.array(goal, np.float32), "t": int(t)}
        return ob, info

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        key = jax.random.PRNGKey(int(self.np_random.integers(0, _SEED_HIGH)))
        self._state = self._env.jit_reset(key)
        return self._observe()

    def step(self, action):
        a = _checked_actions(self, action, "action")
        self._state = self._env.jit_step(self._state, a)
        ob, info = self._observe()
        reward, done = jax.device_get((self._state.reward, self._state.done))
        # The only end is the horizon, a time limit: truncated, never terminated.
        return ob, float(reward), False, bool(done), info

    def render(self):
        return _rgb_frames(self)


class RollGoalVectorEnv(_GoalReward, VectorEnv):
    """N copies of one task stepped in one jitted, vmapped call (`env.jit_vstep`); an env
    whose episode ended is reset on the next step call (`AutoresetMode.NEXT_STEP`: that call
    ignores its action and returns its first observation, reward 0). Seeds: `reset(seed=s)`
    seeds env i with s + i, as Gymnasium's SyncVectorEnv does, so env i matches a single env
    reset with seed s + i."""

    metadata = {"render_modes": list(RENDER_MODES), "render_fps": 10,
                "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(self, task: str = "puck_push", num_envs: int = 1, obs_type: str = "pixels",
                 render_mode: str | None = None, **config):
        if not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
            raise ValueError(f"num_envs must be a positive int, got {num_envs!r}")
        _check_render_mode(render_mode)
        self._env = _load(task, obs_type, config)
        self.task = self._env.task
        # real time: 10 frames per second, the door's 0.15 s steps 6.67
        self.metadata = {**self.metadata, "render_fps": 1.0 / self._env.dt}
        self.obs_type = obs_type
        self.num_envs = int(num_envs)
        self.render_mode = render_mode
        self.single_observation_space = goal_spaces(self._env)
        self.single_action_space = spaces.Box(-1.0, 1.0, (self._env.action_size,), np.float32)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._env_rngs: list[np.random.Generator | None] = [None] * self.num_envs
        self._state = None
        self._autoreset = np.zeros(self.num_envs, bool)

    @property
    def roll_env(self) -> RollEnv:
        return self._env

    def _keys(self, which) -> jax.Array:
        keys = np.zeros((self.num_envs, 2), np.uint32)
        for i in np.flatnonzero(which):
            keys[i] = np.asarray(jax.random.PRNGKey(
                int(self._env_rngs[i].integers(0, _SEED_HIGH))))
        return jnp.asarray(keys)

    def _observe(self):
        s = self._state
        obs, goal, goal_image, dist, qpos = jax.device_get((
            s.obs, s.info["goal"], s.info.get("goal_image"), s.metrics["goal_distance"],
            s.data.qpos))
        ob = _split_obs(self._env, obs, goal, goal_image)
        ones = np.ones(self.num_envs, bool)
        info = {"goal_distance": np.asarray(dist, np.float32), "_goal_distance": ones,
                "achieved_object": _object_of(self._env, qpos), "_achieved_object": ones.copy(),
                "desired_object": np.array(goal, np.float32), "_desired_object": ones.copy()}
        return ob, info

    def reset(self, *, seed: int | list[int | None] | None = None,
              options: dict[str, Any] | None = None):
        super().reset(seed=seed if isinstance(seed, int) else None)
        if seed is None:
            seeds = [None] * self.num_envs
        elif isinstance(seed, (int, np.integer)):
            seeds = [int(seed) + i for i in range(self.num_envs)]
        else:
            seeds = list(seed)
            if len(seeds) != self.num_envs:
                raise ValueError(f"{len(seeds)} seeds for num_envs={self.num_envs}")
        for i, s in enumerate(seeds):
            if s is not None or self._env_rngs[i] is None:
                self._env_rngs[i], _ = seeding.np_random(s)
        self._state = self._env.jit_vreset(self._keys(np.ones(self.num_envs, bool)))
        self._autoreset = np.zeros(self.num_envs, bool)
        return self._observe()

    def step(self, actions):
        a = _checked_actions(self, actions, "actions")
        mask = self._autoreset
        if not mask.any():
            self._state = self._env.jit_vstep(self._state, a)
        elif mask.all():
            self._state = self._env.jit_vreset(self._keys(mask))
        else:  # some envs finished earlier than others
            stepped = self._env.jit_vstep(self._state, a)
            fresh = self._env.jit_vreset(self._keys(mask))
            self._state = _where_first_axis(jnp.asarray(mask), fresh, stepped)
        ob, info = self._observe()
        reward, done = jax.device_get((self._state.reward, self._state.done))
        truncated = np.asarray(done, bool).copy()
        terminated = np.zeros(self.num_envs, bool)
        self._autoreset = truncated | terminated
        return ob, np.asarray(reward, np.float32), terminated, truncated, info

    def render(self):
        frames = _rgb_frames(self)
        return None if frames is None else tuple(frames)


@jax.jit
def _where_first_axis(mask, a, b):
    def pick(x, y):
        return jnp.where(mask.reshape(mask.shape + (1,) * (x.ndim - 1)), x, y)

    return jax.tree.map(pick, a, b)
