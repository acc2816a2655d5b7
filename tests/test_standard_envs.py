"""The Playground-style environments (envs_mjx.standard, envs_mjx.registry): the contract,
reward = -goal distance, done at the horizon, jit(vmap) parity. Everything runs on
puck_push with the default config, whose programs (env.jit_reset / jit_step / jit_vreset /
jit_vstep) the Gymnasium tests share: each is compiled once per process."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from envs_mjx import registry, standard

N = 3


@pytest.fixture(scope="module")
def env():
    return registry.load("PuckPush")


@pytest.fixture(scope="module")
def episode(env):
    """One episode to the horizon with fixed random actions: the states after reset and after
    every step."""
    actions = np.random.default_rng(0).uniform(-1, 1, (env.horizon, env.action_size))
    states = [env.jit_reset(jax.random.PRNGKey(3))]
    for a in actions.astype(np.float32):
        states.append(env.jit_step(states[-1], a))
    return states


# ----------------------------------------------------------------- registry, bad input
def test_registry_names_and_instances():
    assert registry.ALL_ENVS == ("PuckPush", "HurdleBottom", "HurdleTop", "DoorOpen", "Pickup")
    a = registry.load("PuckPush")
    assert registry.load("puck_push") is a  # a task name works too; one instance per config
    assert registry.load("PuckPush", obs_type="state") is not a
    assert registry.load("PuckPush", config={"obs_type": "state"}) is registry.load(
        "PuckPush", config_overrides={"obs_type": "state"})
    assert registry.get_default_config("DoorOpen") == standard.Config(ctrl_dt=0.15)
    assert registry.load("DoorOpen").dt == pytest.approx(0.15)  # the reference's 3 ms x 50


@pytest.mark.parametrize("kwargs, pattern", [
    ({"name": "PuckPull"}, r"'PuckPull'.*PuckPush, HurdleBottom, HurdleTop, DoorOpen, Pickup"),
    ({"obs_type": "rgb"}, r"obs_type 'rgb'.*'pixels', 'state'"),
    ({"obs_typ": "state"}, r"'obs_typ'.*valid fields: obs_type, goal_in_obs"),
    ({"image_size": 0}, r"image_size must be a positive int, got 0"),
    ({"episode_length": -1}, r"episode_length must be a positive int or None, got -1"),
    ({"ctrl_dt": 0.05}, r"ctrl_dt is fixed by the scene of 'puck_push' \(0.1\), got 0.05"),
    ({"sim_dt": 0.002}, r"sim_dt is fixed by the scene \(0.01\), got 0.002"),
])
def test_bad_config_names_the_value_and_the_choices(kwargs, pattern):
    kwargs = {"name": "PuckPush", **kwargs}
    with pytest.raises(ValueError, match=pattern):
        registry.load(**kwargs)


def test_sizes_and_playground_properties():
    pix, st = registry.load("PuckPush"), registry.load("PuckPush", obs_type="state")
    assert pix.observation_size == (48, 48, 6) and pix.action_size == 2
    assert registry.load("PuckPush", goal_in_obs=False).observation_size == (48, 48, 3)
    assert st.observation_size == 3 + 2 + 2  # hand xyz, puck xy, goal xy
    assert registry.load("Pickup", obs_type="state").observation_size == 3 + 2 + 3 + 3
    assert registry.load("DoorOpen", obs_type="state").observation_size == 3 + 1 + 1
    assert registry.load("DoorOpen").episode_length == 100
    assert pix.dt == pytest.approx(0.1) and pix.sim_dt == pytest.approx(0.01)
    assert pix.n_substeps == 10 and pix.unwrapped is pix
    assert pix.mj_model is pix.base.mj_model and pix.mjx_model is pix.base.mjx_model
    for e in (pix, st):  # observation_size agrees with what reset returns (traced only)
        obs = jax.eval_shape(e.reset, jax.random.PRNGKey(0)).obs
        size = e.observation_size
        assert obs.shape == (size if isinstance(size, tuple) else (size,))
    assert obs.dtype == jnp.float32
    if standard.HAVE_PLAYGROUND:
        import mujoco_playground

        assert isinstance(pix, mujoco_playground.MjxEnv)


# ----------------------------------------------------------------- the contract
def test_reset_draws_a_goal_and_fills_every_field(env, episode):
    s = episode[0]
    assert set(s.info) == {"goal", "goal_image", "t", "truncation"}
    assert set(s.metrics) == {"goal_distance", "final_goal_distance"}
    assert s.obs.shape == (48, 48, 6) and s.obs.dtype == jnp.uint8
    assert float(s.reward) == 0.0 and float(s.done) == 0.0 and int(s.info["t"]) == 0
    spec = env.base.spec
    goal = np.asarray(s.info["goal"])
    assert np.all(goal >= np.asarray(spec.object_goal_low) - 1e-6)
    assert np.all(goal <= np.asarray(spec.object_goal_high) + 1e-6)
    # the goal image is the one stacked after the current image
    np.testing.assert_array_equal(np.asarray(s.obs[..., 3:]), np.asarray(s.info["goal_image"]))
    # different keys, different goals
    other = env.jit_reset(jax.random.PRNGKey(4))
    assert not np.allclose(np.asarray(other.info["goal"]), goal)


def test_reward_is_minus_the_goal_distance(env, episode):
    base = env.base
    for s in episode[1:]:
        obj = np.asarray(base.object_state(env.base_state(s)))
        want = np.linalg.norm(obj - np.asarray(s.info["goal"]))
        assert float(s.reward) == pytest.approx(-want, abs=1e-6)
        assert float(s.metrics["goal_distance"]) == pytest.approx(want, abs=1e-6)
        # final_goal_distance: the distance at the last step only (summed: the final distance)
        last = int(s.info["t"]) == env.episode_length
        assert float(s.metrics["final_goal_distance"]) == pytest.approx(want * last, abs=1e-6)
    assert float(episode[-1].info["t"]) == env.horizon
    # the goal stays the same through the episode
    np.testing.assert_array_equal(np.asarray(episode[0].info["goal"]),
                                  np.asarray(episode[-1].info["goal"]))
    # the render of the current state is in obs, and matches `render`
    last = episode[-1]
    np.testing.assert_array_equal(env.render(last), np.asarray(last.obs[..., :3]))
    frames = env.render(episode[:2])
    assert isinstance(frames, list) and len(frames) == 2
    with pytest.raises(ValueError, match=r"one camera; got camera='top'"):
        env.render(last, camera="top")


def test_done_exactly_at_the_horizon(env, episode):
    done = [float(s.done) for s in episode]
    trunc = [float(s.info["truncation"]) for s in episode]
    assert done == [0.0] * env.horizon + [1.0]
    assert trunc == done
    assert env.episode_length == env.horizon == 50


def test_jit_vmap_step_matches_the_single_env(env):
    keys = jax.random.split(jax.random.PRNGKey(11), N)
    batch = env.jit_vreset(keys)  # jax.jit(jax.vmap(env.reset))
    actions = np.random.default_rng(1).uniform(-1, 1, (N, env.action_size)).astype(np.float32)
    stepped = env.jit_vstep(batch, actions)  # jax.jit(jax.vmap(env.step))
    assert stepped.obs.shape == (N, 48, 48, 6) and stepped.reward.shape == (N,)
    for i in range(N):
        single = env.jit_reset(keys[i])
        np.testing.assert_allclose(np.asarray(single.info["goal"]),
                                   np.asarray(batch.info["goal"][i]), atol=1e-6)
        one = env.jit_step(single, actions[i])
        np.testing.assert_allclose(float(one.reward), float(stepped.reward[i]), atol=1e-4)
        np.testing.assert_allclose(np.asarray(one.data.qpos), np.asarray(stepped.data.qpos[i]),
                                   atol=1e-4)
        diff = np.abs(np.asarray(one.obs, np.int32) - np.asarray(stepped.obs[i], np.int32))
        assert diff.mean() < 1.0, diff.mean()  # a few pixels may differ by rounding


def test_state_tree_replace(episode):
    s = episode[1]
    r = s.tree_replace({"info.t": jnp.asarray(7, jnp.int32), "reward": jnp.zeros(())})
    assert int(r.info["t"]) == 7 and float(r.reward) == 0.0
    assert int(s.info["t"]) == 1  # the original is unchanged


def test_goal_distance_is_the_door_angle_error():
    door = registry.load("DoorOpen")
    d = door.goal_distance(jnp.array([[0.5], [0.1]]), jnp.array([[0.2], [0.4]]))
    np.testing.assert_allclose(np.asarray(d), [0.3, 0.3], atol=1e-6)


def test_config_is_a_frozen_dataclass():
    cfg = standard.make_config({"obs_type": "state", "episode_length": 10})
    assert dataclasses.asdict(cfg)["episode_length"] == 10
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.obs_type = "pixels"
