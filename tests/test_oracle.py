"""`--algo oracle`: the real chunk with true positions for latents and no images."""

import jax
import numpy as np
import pytest

import envs_mjx
from configs.train import make_config
from roll_jax.encoders import oracle, pretrain
from roll_jax.encoders.goal_encoding import Frozen, goal_encoder
from roll_jax.training import loop
from roll_jax.training import state as train_state


@pytest.fixture(scope="module")
def chunk_out():
    """One chunk of the "step" SAC schedule from step 0 (SAC learns during it: the cpu
    preset's schedule; the smoke ROLL runs of test_train cover "epoch"), and the initial state
    it started from (the schedule test below starts its variants there too)."""
    import dataclasses

    base = make_config("puck_push", "oracle", "smoke", seeds=1, n_eval_goals=2,
                       sac_schedule="step")
    cfg = dataclasses.replace(base, sac=dataclasses.replace(base.sac, learning_starts=0))
    env = envs_mjx.make("puck_push")
    pre = pretrain.initial(cfg, jax.random.PRNGKey(0))
    state = jax.jit(lambda k: train_state.init_state(k, cfg, env, pre.scene_vae, pre.lstm))(
        jax.random.PRNGKey(1))
    chunk = jax.jit(loop.make_chunk(cfg, env))
    new, metrics = chunk(state, Frozen(seg=None, object_vae=None), train_state.plan_chunk(cfg, 0))
    return cfg, env, new, metrics, state, chunk


def test_oracle_stores_true_positions(chunk_out):
    cfg, env, state, *_ = chunk_out
    enc = goal_encoder(cfg)
    assert isinstance(enc, oracle.StateOracle) and not enc.from_pixels
    assert not enc.segment and not enc.lstm
    buf = state.buffer
    n = cfg.n_envs * cfg.episodes_per_epoch
    assert int(buf.size) == n
    assert buf.images.shape[2:] == (1, 1, 3) and not np.any(np.asarray(buf.images))
    obs, goal = np.asarray(buf.obs_latents[:n]), np.asarray(buf.goal_latents[:n])
    assert obs.shape[-1] == 3 + env.object_size and goal.shape[-1] == env.object_size
    # The observation's object part is the achieved goal; the frame latents are the same.
    np.testing.assert_array_equal(obs[..., 3:], goal)
    np.testing.assert_array_equal(np.asarray(buf.frame_latents[:n]), goal)
    # The last stored frame is the envs' final state, centred, in units of ORACLE_SCALE metres.
    last = state.env_state
    centre = oracle.oracle_centre(env)
    hand = (np.asarray(jax.vmap(env.hand_pos)(last)) - centre[:3]) / oracle.ORACLE_SCALE
    puck = (np.asarray(jax.vmap(env.object_state)(last)) - centre[3:]) / oracle.ORACLE_SCALE
    np.testing.assert_allclose(obs[-cfg.n_envs:, -1, :3], hand, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(goal[-cfg.n_envs:, -1], puck, rtol=1e-5, atol=1e-5)
    # The (untrained, stochastic) policy moves the hand: the episode is not a constant.
    assert np.ptp(obs[..., :3], axis=1).max() > 0.1


def test_oracle_evaluates_with_a_rendered_video(chunk_out):
    cfg, _env, _state, metrics, *_ = chunk_out
    ev = metrics["eval"]
    d = np.asarray(ev["distances"])
    assert d.shape == (cfg.n_eval_goals * cfg.episodes_per_epoch,) and np.all(np.isfinite(d))
    video = np.asarray(ev["video"])
    assert video.shape == (cfg.horizon + 1, 48, 48, 3) and video.std() > 0
    assert np.asarray(ev["goal_image"]).shape == (48, 48, 3)


def test_oracle_goal_bank_lies_in_the_goal_space():
    env = envs_mjx.make("puck_push")
    enc = oracle.StateOracle()
    bank = np.asarray(jax.jit(lambda k: enc.goal_bank(env, k))(jax.random.PRNGKey(0)))
    assert bank.shape == (oracle.ORACLE_BANK, env.object_size)
    lo, hi = bank.min(0), bank.max(0)
    assert np.all(hi - lo > 0.5)  # spread over the box (> 5 cm per axis)
    assert np.all(np.abs(bank.mean(0)) < 0.2)  # centred: the goal space's middle is 0
    # jitted: MJX op by op dispatches hundreds of small programs
    goal_state = jax.jit(env.sample_goal)(jax.random.PRNGKey(7))
    goal = np.asarray(jax.jit(env.object_state)(goal_state))
    np.testing.assert_allclose(
        jax.jit(lambda s: enc.goal(env, s))(goal_state),
        (goal - oracle.oracle_centre(env)[3:]) / oracle.ORACLE_SCALE, rtol=1e-6)


def test_step_schedule_learns_during_collection_and_evaluates_the_start_policy(chunk_out):
    """sac_schedule "step": the updates run inside the episode (the SAC state after the chunk
    has them all; the training envs' actions differ from those of a chunk that does not
    learn), while the test envs act with the policy the chunk started from: their distances
    equal those of that chunk. A chunk without the test envs (`evaluate` False) trains
    exactly as the one with them."""
    cfg, env, s_state, s_m, start, chunk = chunk_out
    assert cfg.sac_schedule == "step" and cfg.sac.learning_starts == 0
    frozen = Frozen(seg=None, object_vae=None)
    plan = train_state.plan_chunk(cfg, 0)
    assert bool(plan.learn) and not bool(plan.act_random)
    # The same program and start, SAC off: the policy stays the one the chunk started with.
    f_state, f_m = chunk(start, frozen, plan.replace(learn=jax.numpy.bool_(False)))
    assert int(f_state.sac.step) == 0
    n_state, n_m = jax.jit(loop.make_chunk(cfg, env, False))(start, frozen, plan)
    # Without the test envs the chunk trains the same: the same episodes, the same updates.
    assert "eval" not in n_m
    np.testing.assert_array_equal(np.asarray(n_state.buffer.actions),
                                  np.asarray(s_state.buffer.actions))
    np.testing.assert_array_equal(np.asarray(n_state.buffer.obs_latents),
                                  np.asarray(s_state.buffer.obs_latents))
    for a, b in zip(jax.tree.leaves(n_state.sac), jax.tree.leaves(s_state.sac)):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-5, atol=1e-6)
    n_updates = cfg.epoch_env_steps * cfg.sac.updates_per_step
    assert int(s_state.sac.step) == n_updates
    np.testing.assert_allclose(np.asarray(s_m["eval"]["distances"]),
                               np.asarray(f_m["eval"]["distances"]), rtol=1e-6, atol=1e-7)
    # The training envs acted with a policy that changed during the episode: other actions.
    assert not np.allclose(np.asarray(s_state.buffer.actions), np.asarray(f_state.buffer.actions))
    assert np.isfinite(float(s_m["train"]["q_loss"])) and float(s_m["train"]["q_loss"]) != 0.0
