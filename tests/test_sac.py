"""SAC: config validation, loss signs, target update, one-step probe environments."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from configs.sac import SACConfig
from roll_jax.agents import sac

OBS, GOAL, ACT = 3, 2, 2
SMALL = SACConfig(hidden=(32, 32), batch_size=64, policy_lr=3e-3, q_lr=3e-3, alpha_lr=3e-3)
# Eager op-by-op dispatch of an update is slower than compiling it.
update = jax.jit(sac.sac_update, static_argnames="cfg")
init = jax.jit(sac.init_sac, static_argnums=(1, 2, 3, 4))


def _batch(key, n, reward_fn=None, done=1.0):
    k1, k2, k3, k4 = jax.random.split(key, 4)
    obs = jax.random.normal(k1, (n, OBS))
    goal = jax.random.normal(k2, (n, GOAL))
    action = jax.random.uniform(k3, (n, ACT), minval=-1, maxval=1)
    reward = jnp.ones((n,)) if reward_fn is None else reward_fn(action)
    return sac.Transition(obs=obs, goal=goal, action=action, reward=reward,
                          next_obs=jax.random.normal(k4, (n, OBS)), done=jnp.full((n,), done))


def _train(cfg, n_steps, make_batch, seed=0):
    """n_steps of sac_update in one lax.scan; batches are built inside from the step key."""
    state = init(jax.random.key(seed), OBS, GOAL, ACT, cfg)

    @jax.jit
    def run(state, key):
        def body(state, k):
            kb, ku = jax.random.split(k)
            return sac.sac_update(state, ku, make_batch(kb), cfg)
        return jax.lax.scan(body, state, jax.random.split(key, n_steps))

    return run(state, jax.random.key(seed + 1))


def test_config_defaults_and_validation():
    cfg = SACConfig()
    assert cfg.hidden == (400, 300) and cfg.batch_size == 1024 and cfg.tau == 1e-3
    assert cfg.goal_fracs == (0.2, 0.5, 0.3)
    assert cfg.entropy_target(4) == -4.0
    assert cfg.replay_capacity(100) == 1000
    with pytest.raises(ValueError, match="sum to 1"):
        SACConfig(future_goal_frac=0.4)
    with pytest.raises(ValueError, match="batch_size.*0"):
        SACConfig(batch_size=0)
    with pytest.raises(ValueError, match="replay_size"):
        SACConfig(replay_size=-5)
    with pytest.raises(ValueError, match="discount"):
        SACConfig(discount=1.5)
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.tau = 0.5


def test_shapes_and_select_action():
    state = init(jax.random.key(0), OBS, GOAL, ACT, SMALL)
    obs, goal = jnp.zeros((5, OBS)), jnp.zeros((5, GOAL))
    a = sac.select_action(state.policy_params, obs, goal, jax.random.key(1))
    assert a.shape == (5, ACT) and bool(jnp.all(jnp.abs(a) <= 1))
    a_det = sac.select_action(state.policy_params, obs[0], goal[0], None, deterministic=True)
    assert a_det.shape == (ACT,)
    assert sac.q_values(state.q_params, obs, goal, a).shape == (2, 5)
    # Default sizes: 400-300 MLPs read back from params.
    big = init(jax.random.key(0), OBS, GOAL, ACT, SACConfig())
    assert sac._mlp_sizes(big.policy_params["params"]) == ((400, 300), 2 * ACT)


def test_select_action_uses_config_log_std_bounds():
    # Policy with mean 0 and raw log_std 5: the clip alone sets the spread of sampled actions.
    state = init(jax.random.key(0), OBS, GOAL, ACT, SMALL)
    pp = jax.tree.map(lambda x: x, state.policy_params)
    out = pp["params"]["out"]
    out["kernel"] = jnp.zeros_like(out["kernel"])
    out["bias"] = jnp.concatenate([jnp.zeros(ACT), jnp.full(ACT, 5.0)])
    obs, goal = jnp.zeros((256, OBS)), jnp.zeros((256, GOAL))
    key = jax.random.key(1)
    narrow = dataclasses.replace(SMALL, log_std_min=-12.0, log_std_max=-10.0)
    a_narrow = sac.select_action(pp, obs, goal, key, cfg=narrow)
    a_default = sac.select_action(pp, obs, goal, key)
    # std = exp(-10): actions ~ tanh(0) = 0; default clip (max 2, std ~ 7.4): spread over [-1, 1].
    assert float(jnp.abs(a_narrow).max()) < 1e-3
    assert float(jnp.abs(a_default).mean()) > 0.5
    # Acting draws what training's sample_action draws under the same config and key.
    np.testing.assert_array_equal(a_narrow, sac.sample_action(pp, obs, goal, key, narrow)[0])
    # cfg=None is the SACConfig defaults.
    np.testing.assert_array_equal(a_default, sac.select_action(pp, obs, goal, key, cfg=SACConfig()))


def test_tanh_gaussian_log_prob_matches_change_of_variables():
    mean, log_std = jnp.array([[0.3, -0.7]]), jnp.array([[-0.5, 0.2]])
    a, logp = sac._tanh_gaussian_sample(jax.random.key(3), mean, log_std)
    u = np.arctanh(np.asarray(a, np.float64))
    std = np.exp(np.asarray(log_std, np.float64))
    ref = np.sum(-0.5 * ((u - mean) / std) ** 2 - np.log(std) - 0.5 * np.log(2 * np.pi)
                 - np.log(1 - np.tanh(u) ** 2), axis=-1)
    np.testing.assert_allclose(logp, ref, rtol=1e-4)


def test_target_moves_by_tau():
    cfg = SMALL  # tau = 1e-3 (Table 4); same compiled update as the other tests
    state = init(jax.random.key(0), OBS, GOAL, ACT, cfg)
    # Make target differ from online so the formula is visible.
    state = state.replace(target_q_params=jax.tree.map(lambda x: x + 1.0, state.target_q_params))
    new, metrics = update(state, jax.random.key(1), _batch(jax.random.key(2), 16), cfg)
    expected = jax.tree.map(lambda q, t: cfg.tau * q + (1 - cfg.tau) * t, new.q_params, state.target_q_params)
    for e, t in zip(jax.tree.leaves(expected), jax.tree.leaves(new.target_q_params)):
        np.testing.assert_allclose(t, e, rtol=1e-6, atol=1e-6)
    assert int(new.step) == 1 and bool(metrics["finite"])
    for k in ("q_loss", "policy_loss", "alpha", "alpha_loss", "q_mean", "entropy"):
        assert k in metrics


def test_target_update_period_skips_steps():
    cfg = dataclasses.replace(SMALL, tau=0.5, target_update_period=2)
    state = init(jax.random.key(0), OBS, GOAL, ACT, cfg)
    new, _ = update(state, jax.random.key(1), _batch(jax.random.key(2), 16), cfg)
    for a, b in zip(jax.tree.leaves(state.target_q_params), jax.tree.leaves(new.target_q_params)):
        np.testing.assert_array_equal(a, b)


def test_alpha_loss_sign():
    # Entropy above target (log pi very negative) -> d loss / d log_alpha > 0 -> alpha decreases.
    g_high = jax.grad(sac.alpha_loss)(jnp.float32(0.0), jnp.full((8,), -5.0), -2.0)
    g_low = jax.grad(sac.alpha_loss)(jnp.float32(0.0), jnp.full((8,), 5.0), -2.0)
    assert g_high > 0 and g_low < 0
    # Through a full update: the initial policy (std ~ 1) has entropy > -action_dim.
    state = init(jax.random.key(0), OBS, GOAL, ACT, SMALL)
    new, metrics = update(state, jax.random.key(1), _batch(jax.random.key(2), 64), SMALL)
    assert float(metrics["entropy"]) > -ACT
    assert float(new.log_alpha) < float(state.log_alpha)


def test_critic_loss_zero_at_fixed_point():
    # done = 1: y = reward_scale * r; set Q's output bias to y with zero out-kernel -> loss 0.
    cfg = dataclasses.replace(SMALL, reward_scale=2.0)
    state = init(jax.random.key(0), OBS, GOAL, ACT, cfg)
    qp = jax.tree.map(lambda x: x, state.q_params)
    for q in ("q1", "q2"):
        qp["params"][q]["out"]["kernel"] = jnp.zeros_like(qp["params"][q]["out"]["kernel"])
        qp["params"][q]["out"]["bias"] = jnp.full_like(qp["params"][q]["out"]["bias"], 2.0)
    loss, aux = jax.jit(sac.critic_loss, static_argnums=6)(qp, state.target_q_params, state.policy_params, 1.0,
                                _batch(jax.random.key(1), 16), jax.random.key(2), cfg)
    assert float(loss) < 1e-10 and float(aux["q_target_mean"]) == pytest.approx(2.0)


def test_nan_is_flagged():
    state = init(jax.random.key(0), OBS, GOAL, ACT, SMALL)
    b = _batch(jax.random.key(1), 16)
    b = b.replace(reward=b.reward.at[0].set(jnp.nan))
    _, metrics = update(state, jax.random.key(2), b, SMALL)
    assert not bool(metrics["finite"])


def test_probe_constant_reward_q_converges_to_one():
    state, metrics = _train(SMALL, 600, lambda k: _batch(k, 64))
    obs, goal = jax.random.normal(jax.random.key(9), (256, OBS)), jax.random.normal(jax.random.key(8), (256, GOAL))
    a = jax.random.uniform(jax.random.key(7), (256, ACT), minval=-1, maxval=1)
    q = sac.q_values(state.q_params, obs, goal, a)
    print(f"probe 1: learned Q mean {float(q.mean()):.4f} (target 1), max |Q-1| {float(jnp.abs(q - 1).max()):.4f}")
    assert float(jnp.abs(q - 1.0).mean()) < 0.02 and float(jnp.abs(q - 1.0).max()) < 0.15
    assert bool(jnp.all(metrics["finite"]))


def test_probe_quadratic_reward_policy_finds_a_star():
    a_star = jnp.array([0.5, -0.3])
    state, metrics = _train(SMALL, 1500, lambda k: _batch(k, 64, lambda a: -jnp.sum((a - a_star) ** 2, -1)))
    obs, goal = jax.random.normal(jax.random.key(9), (256, OBS)), jax.random.normal(jax.random.key(8), (256, GOAL))
    a = sac.select_action(state.policy_params, obs, goal, None, deterministic=True)
    err = jnp.abs(a.mean(0) - a_star)
    print(f"probe 2: policy mean {np.round(np.asarray(a.mean(0)), 3)} vs a* {np.asarray(a_star)}, "
          f"max err {float(err.max()):.3f}, alpha {float(metrics['alpha'][-1]):.4f}")
    assert float(err.max()) < 0.1
    assert bool(jnp.all(metrics["finite"]))
