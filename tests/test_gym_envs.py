"""The Gymnasium environments (envs_mjx.gym): registration, check_env on every task, the
goal-conditioned Dict spaces, compute_reward, make_vec against single envs, bad input. The
envs run the Playground-style env's cached programs, so each task's reset and step compile
once per process (shared with tests/test_standard_envs.py)."""

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import envs_mjx  # registers the ids
from envs_mjx import gym as roll_gym
from envs_mjx import registry

IDS = registry.GYM_IDS
N = 3


def test_import_registers_the_five_ids_with_a_vector_entry_point():
    assert IDS == ("roll/PuckPush-v0", "roll/HurdleBottom-v0", "roll/HurdleTop-v0",
                   "roll/DoorOpen-v0", "roll/Pickup-v0")
    for gym_id in IDS:
        spec = gymnasium.spec(gym_id)
        assert spec.entry_point == "envs_mjx.gym:RollGoalEnv"
        assert spec.vector_entry_point == "envs_mjx.gym:RollGoalVectorEnv"
    assert registry.register_gymnasium()  # idempotent
    assert envs_mjx.registry is registry


@pytest.mark.parametrize("gym_id", IDS)
def test_check_env_pixels(gym_id):
    env = gymnasium.make(gym_id, render_mode="rgb_array")
    check_env(env.unwrapped)
    obs, info = env.reset(seed=1)
    assert obs["observation"].shape == (48, 48, 3) and obs["observation"].dtype == np.uint8
    assert obs["desired_goal"].shape == (48, 48, 3)
    np.testing.assert_array_equal(obs["observation"], obs["achieved_goal"])
    assert env.render().shape == (48, 48, 3)
    # the env's reward is compute_reward of its own goals (Gymnasium-Robotics' contract)
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    want = env.unwrapped.compute_reward(obs["achieved_goal"], obs["desired_goal"], info)
    assert reward == pytest.approx(float(want), abs=1e-6)
    assert reward == pytest.approx(-info["goal_distance"], abs=1e-6)
    assert not terminated and not truncated
    # videos play in real time: one frame per env step (0.1 s; the door's 0.15 s)
    assert env.metadata["render_fps"] == pytest.approx(
        1 / 0.15 if gym_id == "roll/DoorOpen-v0" else 10.0)
    env.close()


def test_check_env_state_and_a_whole_episode():
    env = gymnasium.make("roll/PuckPush-v0", obs_type="state", render_mode="rgb_array")
    check_env(env.unwrapped)
    space = env.observation_space
    assert space["observation"].shape == (5,) and space["desired_goal"].shape == (2,)
    obs, info = env.reset(seed=5)
    np.testing.assert_array_equal(obs["achieved_goal"], obs["observation"][3:])
    np.testing.assert_array_equal(obs["desired_goal"], info["desired_object"])
    env.action_space.seed(5)
    steps, truncated = 0, False
    while not truncated:
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        steps += 1
        assert not terminated
        want = -np.linalg.norm(obs["achieved_goal"] - obs["desired_goal"])
        assert reward == pytest.approx(want, abs=1e-6)
    assert steps == 50 == info["t"]
    assert env.render().shape == (48, 48, 3)


def test_compute_reward_is_vectorised():
    env = gymnasium.make("roll/PuckPush-v0", obs_type="state").unwrapped
    rng = np.random.default_rng(0)
    ag, dg = rng.normal(size=(4, 5, 2)), rng.normal(size=(4, 5, 2))
    r = env.compute_reward(ag, dg, [{}] * 5)
    assert r.shape == (4, 5)
    np.testing.assert_allclose(r, -np.linalg.norm(ag - dg, axis=-1), rtol=1e-6)
    # pixel goals: the object states of the info (one dict of arrays or a list of dicts)
    pix = gymnasium.make("roll/PuckPush-v0").unwrapped
    img = np.zeros((5, 48, 48, 3), np.uint8)
    info = {"achieved_object": ag[0], "desired_object": dg[0]}
    np.testing.assert_allclose(pix.compute_reward(img, img, info), r[0], rtol=1e-6)
    infos = [{"achieved_object": a, "desired_object": d} for a, d in zip(ag[0], dg[0])]
    np.testing.assert_allclose(pix.compute_reward(img, img, infos), r[0], rtol=1e-6)
    with pytest.raises(ValueError, match="needs the object states in info"):
        pix.compute_reward(img, img, {})
    # door: the angle error
    np.testing.assert_allclose(
        roll_gym._object_distance("door", [[0.5], [0.1]], [[0.2], [0.4]]), [0.3, 0.3],
        atol=1e-6)


def test_make_vec_steps_all_envs_in_one_call_and_matches_single_envs():
    venv = gymnasium.make_vec("roll/PuckPush-v0", num_envs=N)
    assert isinstance(venv, roll_gym.RollGoalVectorEnv)
    assert isinstance(venv, gymnasium.vector.VectorEnv)
    assert venv.metadata["autoreset_mode"] == gymnasium.vector.AutoresetMode.NEXT_STEP
    assert venv.observation_space["observation"].shape == (N, 48, 48, 3)
    assert venv.action_space.shape == (N, 2)
    roll = venv.roll_env
    calls = []
    original = roll.jit_vstep

    def counted(*args):
        calls.append(1)
        return original(*args)

    roll.__dict__["_jit_vstep"] = counted
    try:
        obs, info = venv.reset(seed=7)
        singles = [gymnasium.make("roll/PuckPush-v0") for _ in range(N)]
        for i, e in enumerate(singles):  # env i of the vector env is seeded 7 + i
            o, inf = e.reset(seed=7 + i)
            for k in o:
                np.testing.assert_array_equal(obs[k][i], o[k])
        horizon = roll.horizon
        actions = np.random.default_rng(2).uniform(-1, 1, (horizon + 2, N, 2)).astype(np.float32)
        for t, a in enumerate(actions):
            obs, reward, terminated, truncated, info = venv.step(a)
            assert not terminated.any()
            assert truncated.all() == (t == horizon - 1)
            for i, e in enumerate(singles):
                if t == horizon:  # next-step autoreset: a new episode, reward 0
                    o, inf = e.reset()
                    r, tr = 0.0, False
                else:
                    o, r, _, tr, inf = e.step(a[i])
                assert truncated[i] == tr and reward[i] == pytest.approx(r, abs=1e-4)
                np.testing.assert_allclose(info["desired_object"][i], inf["desired_object"],
                                           atol=1e-6)
                np.testing.assert_allclose(info["achieved_object"][i], inf["achieved_object"],
                                           atol=1e-4)
                for k in ("observation", "desired_goal"):  # a pixel may differ by rounding
                    diff = np.abs(obs[k][i].astype(np.int32) - o[k])
                    assert diff.mean() < 1.0, (t, i, k, diff.mean())
        # one vmapped call per step that stepped (the autoreset step only resets)
        assert len(calls) == horizon + 1
    finally:
        roll.__dict__["_jit_vstep"] = original
    frames = gymnasium.make_vec("roll/PuckPush-v0", num_envs=N, render_mode="rgb_array")
    frames.reset(seed=0)
    assert len(frames.render()) == N and frames.render()[0].shape == (48, 48, 3)


# ----------------------------------------------------------------- bad input
def test_unknown_id_names_the_value():
    with pytest.raises(gymnasium.error.NameNotFound, match=r"PuckPull.*Did you mean.*PuckPush"):
        gymnasium.make("roll/PuckPull-v0")
    with pytest.raises(ValueError, match=r"'puck_pull'.*PuckPush, HurdleBottom.*Pickup"):
        roll_gym.RollGoalEnv(task="puck_pull")


@pytest.mark.parametrize("kwargs, pattern", [
    ({"obs_type": "rgb"}, r"obs_type 'rgb'.*'pixels', 'state'"),
    ({"render_mode": "ansi"}, r"render_mode 'ansi'.*'rgb_array'"),
    ({"goal_in_obs": False}, r"goal_in_obs is not an option"),
    ({"image_sise": 64}, r"'image_sise'.*valid fields"),
])
def test_bad_arguments_name_the_value_and_the_choices(kwargs, pattern):
    with pytest.raises(ValueError, match=pattern):
        gymnasium.make("roll/PuckPush-v0", **kwargs)
    with pytest.raises(ValueError, match=pattern):
        gymnasium.make_vec("roll/PuckPush-v0", num_envs=2, **kwargs)


def test_bad_actions_and_order():
    env = roll_gym.RollGoalEnv("puck_push")
    with pytest.raises(gymnasium.error.ResetNeeded):
        env.step(np.zeros(2, np.float32))
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"shape \(2,\), got \(3,\)"):
        env.step(np.zeros(3, np.float32))
    with pytest.raises(ValueError, match="not finite"):
        env.step(np.array([0.0, np.nan], np.float32))
    with pytest.raises(ValueError, match="num_envs must be a positive int, got 0"):
        roll_gym.RollGoalVectorEnv("puck_push", num_envs=0)
