"""The state oracle as a goal encoder (`--algo oracle`): `GoalEncoder`'s contract with the
true positions in place of every latent, so that one loop runs both. The observation is the
hand position and the object state, the goal and achieved goal the object state, both
centred on the goal space (`oracle_centre`) and in units of ORACLE_SCALE metres; the reward
is then the true distance. Nothing is rendered for learning (the buffer keeps a 1x1
placeholder image); only the evaluation video and the first test goal's image are drawn.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np

ORACLE_SCALE = 0.1  # metres per oracle latent unit: positions enter the networks / 0.1 m
ORACLE_BANK = 1024  # goal-space object states per chunk for fresh goals (`goal_bank`)


@functools.lru_cache(maxsize=None)
def oracle_centre(env) -> np.ndarray:
    """The mean (hand position, object state) of 256 goal states (a fixed draw): the origin
    of the oracle's coordinates, so that the networks see centred inputs."""
    def mean_position(key):
        states = jax.vmap(env.sample_goal)(jax.random.split(key, 256))
        pos = jnp.concatenate([jax.vmap(env.hand_pos)(states),
                               jax.vmap(env.object_state)(states)], -1)
        return jnp.mean(pos, 0)

    # One compiled program, run now even when called while a chunk is traced (op by op, the
    # 256 MJX placements dispatch hundreds of small programs: ~11 s on 2 cores).
    key = np.zeros(2, np.uint32)  # jax.random.PRNGKey(0), as numpy: no tracer when traced
    return np.asarray(jax.jit(mean_position).lower(key).compile()(key))


def rendered(env, states, show):
    """The frames of env states `show` picks: None (none), an index (one frame) or a slice /
    index array (a batch)."""
    if show is None:
        return None
    picked = jax.tree.map(lambda x: x[show], states)
    return env.render(picked) if isinstance(show, int) else jax.vmap(env.render)(picked)


@dataclasses.dataclass(frozen=True)
class StateOracle:
    """True positions for latents; the methods the loop and the evaluation call are
    `GoalEncoder`'s (the parameters they take are unused)."""

    from_pixels: ClassVar[bool] = False  # nothing rendered, segmented or encoded to learn
    segment: ClassVar[bool] = False
    lstm: ClassVar[bool] = False
    skewed_goals: ClassVar[bool] = False
    object_cfg: ClassVar[None] = None
    image_shape: ClassVar[tuple[int, ...]] = (1, 1, 3)  # the buffer's placeholder image

    def latent_dims(self, env) -> tuple[int, int, int]:
        """(observation, goal, per-frame) sizes: hand xyz + object state, object state twice."""
        return 3 + env.object_size, env.object_size, env.object_size

    def observation(self, env, state):
        """The observation of one env state: hand position and object state, centred
        (`oracle_centre`), / ORACLE_SCALE."""
        pos = jnp.concatenate([env.hand_pos(state), env.object_state(state)])
        return (pos - oracle_centre(env)) / ORACLE_SCALE

    def goal(self, env, state):
        """The goal / achieved goal of one env state: the object part of `observation`."""
        return (env.object_state(state) - oracle_centre(env)[3:]) / ORACLE_SCALE

    def observe(self, env, scene_params, states, show=None):
        """(observations [N, 3 + k], what an episode keeps of the step: the achieved goals
        [N, k], the frames of the envs `show` picks (`rendered`))."""
        del scene_params
        achieved = jax.vmap(lambda st: self.goal(env, st))(states)
        return (jax.vmap(lambda st: self.observation(env, st))(states), achieved,
                rendered(env, states, show))

    def encode_episodes(self, frozen, scene_params, lstm_params, records):
        """(images, goal images, frame latents, achieved goals) of episodes whose steps kept
        `records` [E, T+1, k]: placeholder images, the achieved goals for both latents."""
        del frozen, scene_params, lstm_params
        images = jnp.zeros(records.shape[:2] + self.image_shape, jnp.uint8)
        return images, images, records, records

    def goal_bank(self, env, key, lstm_params=None, stats=None):
        """ORACLE_BANK object states drawn from the task's goal space: what a chunk's fresh
        goals are drawn from."""
        del lstm_params, stats
        return jax.vmap(lambda k: self.goal(env, env.sample_goal(k)))(
            jax.random.split(key, ORACLE_BANK))

    def test_goal_images(self, env, states):
        """Only the first goal's image [1, 48, 48, 3]: the evaluation video shows it."""
        return env.render(jax.tree.map(lambda x: x[0], states))[None]

    def encode_goals(self, env, frozen, scene_params, lstm_params, rgb, states):
        """The goals of goal env `states` [G] (their images are not used) -> [G, k]."""
        del frozen, scene_params, lstm_params, rgb
        return jax.vmap(lambda st: self.goal(env, st))(states)
