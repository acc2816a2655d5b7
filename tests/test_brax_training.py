"""Brax's trainers on the Playground-style envs (envs_mjx.brax_training): the wrapper stack
truncates at the episode length and resets a done env to a new start and goal, and Brax's own
SAC trains through it (a smoke of `python -m bench brax_sac`, whose learning curve is in
docs/environments.md)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from envs_mjx import registry
from envs_mjx.brax_training import wrap_for_brax_training

N, LENGTH = 3, 4


@pytest.fixture(scope="module")
def env():
    return registry.load("PuckPush", obs_type="state", done_at_horizon=False,
                         episode_length=LENGTH)


def test_episodes_end_at_the_length_and_restart_with_a_new_goal(env):
    wrapped = wrap_for_brax_training(env, episode_length=LENGTH)
    reset, step = jax.jit(wrapped.reset), jax.jit(wrapped.step)
    state = reset(jax.random.split(jax.random.PRNGKey(0), N))
    goals = [np.asarray(state.info["goal"])]
    actions = jnp.ones((N, env.action_size), jnp.float32)
    for t in range(1, 2 * LENGTH + 1):
        state = step(state, actions)
        done = np.asarray(state.done)
        assert done.tolist() == [float(t % LENGTH == 0)] * N
        np.testing.assert_array_equal(np.asarray(state.info["truncation"]), done)
        goals.append(np.asarray(state.info["goal"]))
        if t % LENGTH:  # mid-episode: same goal, the env's own step count runs on
            np.testing.assert_array_equal(goals[-1], goals[-2])
            assert np.asarray(state.info["t"]).tolist() == [t % LENGTH] * N
        else:  # done: the next episode's start and a new goal, drawn from a fresh key
            assert not np.allclose(goals[-1], goals[-2])
            assert np.asarray(state.info["t"]).tolist() == [0] * N
            fresh_obs = np.asarray(state.obs)
            np.testing.assert_allclose(fresh_obs[:, -2:], goals[-1])  # obs ends with the goal
            # the final distance is reported on the step that ends the episode
            assert np.all(np.asarray(state.metrics["final_goal_distance"]) > 0)
    # the second episode's goals differ from the first's, and every env's from the others'
    assert not np.allclose(goals[LENGTH], goals[2 * LENGTH])
    assert len({tuple(g) for g in goals[-1].round(6)}) == N


def test_an_env_that_ends_its_own_episodes_is_refused(env):
    with pytest.raises(ValueError, match="done_at_horizon=False"):
        wrap_for_brax_training(registry.load("PuckPush", obs_type="state"), episode_length=50)
    with pytest.raises(ValueError, match=r"episode_length=50 .* episode_length=4"):
        wrap_for_brax_training(env, episode_length=50)
    with pytest.raises(ValueError, match="randomization_fn"):
        wrap_for_brax_training(registry.load("PuckPush", obs_type="state",
                                             done_at_horizon=False), 50,
                               randomization_fn=lambda sys, rng: (sys, sys))


def test_brax_sac_trains_on_puck_push(tmp_path):
    """The benchmark's path at a few hundred env steps: Brax's SAC, unchanged, fills its
    replay buffer, updates and evaluates on the env; the result file has the curve."""
    import json

    from bench import brax_sac

    out = tmp_path / "brax_sac.json"
    brax_sac.main(["--steps", "512", "--envs", "4", "--eval-envs", "2", "--evals", "2",
                   "--min-replay", "128", "--updates", "1", "--batch", "16",
                   "--out", str(out), "--png", str(tmp_path / "curve.png")])
    fig = json.loads(out.read_text())["figures"]
    assert [c["env_steps"] for c in fig["curve"]][0] == 0
    assert fig["curve"][-1]["env_steps"] >= 512
    for c in fig["curve"]:  # a puck's distance to a goal in its 30 x 20 cm goal space
        assert 0.0 < c["final_distance_m"] < 0.4
    assert (tmp_path / "curve.png").stat().st_size > 0
