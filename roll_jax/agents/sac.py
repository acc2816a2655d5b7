"""Goal-conditioned SAC (rlkit's SACTrainer, the one Skew-Fit and ROLL use) in JAX.

Networks take concat(obs, goal): obs = scene-VAE latent, goal = object latent (LSTM output).
Twin Q functions with target copies, tanh-Gaussian policy, automatic entropy tuning. All losses
are computed from the same (pre-update) parameters, then the three optimizers step, then the
target Qs move by `tau` (as rlkit's `train_from_torch`).

Usage inside the training loop: `sac_update` is pure; jit it with `cfg` static
(`jax.jit(sac_update, static_argnames="cfg")`) or call it inside the jitted chunk.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import flax.linen as nn
import jax
import jax.numpy as jnp
import optax
from flax import struct

from configs.sac import SACConfig

# --------------------------------------------------------------------------- data

@struct.dataclass
class Transition:
    """A batch of (relabeled) transitions; leading axes are the batch."""
    obs: jax.Array  # [B, ds] scene latent at t
    goal: jax.Array  # [B, dg] object-latent goal
    action: jax.Array  # [B, A] in [-1, 1]
    reward: jax.Array  # [B] unscaled; the critic multiplies by cfg.reward_scale
    next_obs: jax.Array  # [B, ds] scene latent at t+1
    done: jax.Array  # [B] float32 1.0 = terminal (no bootstrap); 0.0 for time-limit ends


@struct.dataclass
class SACState:
    policy_params: dict
    q_params: dict  # twin Qs: {"params": {"q1": ..., "q2": ...}}
    target_q_params: dict
    log_alpha: jax.Array  # scalar
    policy_opt_state: optax.OptState
    q_opt_state: optax.OptState
    alpha_opt_state: optax.OptState
    step: jax.Array  # int32 number of updates done


# --------------------------------------------------------------------------- networks

def _uniform_init(scale: float):
    # rlkit initializes output layers with U(-init_w, init_w) (init_w=1e-3 policy, 3e-3 Q) so the
    # first actions are near tanh(0) with unit std and the first Q values near 0.
    def init(key, shape, dtype=jnp.float32):
        return jax.random.uniform(key, shape, dtype, -scale, scale)
    return init


class MLP(nn.Module):
    """ReLU MLP; layers are named hidden_i / out so sizes can be read back from the params."""
    hidden: Sequence[int]
    out: int
    init_w: float = 3e-3

    @nn.compact
    def __call__(self, x):
        for i, h in enumerate(self.hidden):
            x = nn.relu(nn.Dense(h, name=f"hidden_{i}")(x))
        init = _uniform_init(self.init_w)
        return nn.Dense(self.out, kernel_init=init, bias_init=init, name="out")(x)


class TwinQ(nn.Module):
    hidden: Sequence[int]

    @nn.compact
    def __call__(self, obs, goal, action):
        x = jnp.concatenate([obs, goal, action], axis=-1)
        q1 = MLP(self.hidden, 1, 3e-3, name="q1")(x)[..., 0]
        q2 = MLP(self.hidden, 1, 3e-3, name="q2")(x)[..., 0]
        return jnp.stack([q1, q2])  # [2, ...]


def _mlp_sizes(p: dict) -> tuple[tuple[int, ...], int]:
    """(hidden sizes, output size) of an MLP param dict; shapes are static under jit."""
    n = sum(1 for k in p if k.startswith("hidden_"))
    return tuple(p[f"hidden_{i}"]["kernel"].shape[1] for i in range(n)), p["out"]["kernel"].shape[1]


def policy_dist(policy_params: dict, obs, goal, log_std_min: float = -20.0, log_std_max: float = 2.0):
    """Pre-tanh Gaussian (mean, log_std) of the policy for concat(obs, goal)."""
    hidden, out = _mlp_sizes(policy_params["params"])
    h = MLP(hidden, out, 1e-3).apply(policy_params, jnp.concatenate([obs, goal], axis=-1))
    mean, log_std = jnp.split(h, 2, axis=-1)
    # Hard clip as rlkit (LOG_SIG_MIN/MAX).
    return mean, jnp.clip(log_std, log_std_min, log_std_max)


def q_values(q_params: dict, obs, goal, action):
    """[2, ...] twin Q values."""
    hidden, _ = _mlp_sizes(q_params["params"]["q1"])
    return TwinQ(hidden).apply(q_params, obs, goal, action)


def _tanh_gaussian_sample(key, mean, log_std):
    """Reparameterized tanh-Gaussian sample and its log-probability (summed over action dims)."""
    u = mean + jnp.exp(log_std) * jax.random.normal(key, mean.shape, mean.dtype)
    logp_u = -0.5 * jnp.square((u - mean) / jnp.exp(log_std)) - log_std - 0.5 * math.log(2 * math.pi)
    # log(1 - tanh(u)^2) in the overflow-free form 2 (log 2 - u - softplus(-2u)).
    log_det = 2.0 * (math.log(2.0) - u - jax.nn.softplus(-2.0 * u))
    return jnp.tanh(u), jnp.sum(logp_u - log_det, axis=-1)


def _log_std_bounds(cfg: SACConfig | None) -> tuple[float, float]:
    """(log_std_min, log_std_max) of `cfg`; None means the SACConfig defaults."""
    cfg = SACConfig() if cfg is None else cfg
    return cfg.log_std_min, cfg.log_std_max


def sample_action(policy_params, obs, goal, key, cfg: SACConfig | None = None):
    """(action, log_prob) with the reparameterization trick (gradients flow to the policy)."""
    mean, log_std = policy_dist(policy_params, obs, goal, *_log_std_bounds(cfg))
    return _tanh_gaussian_sample(key, mean, log_std)


def select_action(policy_params, obs, goal, key, deterministic: bool = False, *,
                  cfg: SACConfig | None = None):
    """Action in [-1, 1] for acting: tanh(mean) if deterministic, else a policy sample.

    `cfg` gives the log-std clip (`log_std_min/max`) the sample uses, the same as training's
    `sample_action`; None means the SACConfig defaults. Pass the run's SACConfig so acting and
    training draw from the same distribution.
    """
    if deterministic:
        mean, _ = policy_dist(policy_params, obs, goal, *_log_std_bounds(cfg))
        return jnp.tanh(mean)
    return sample_action(policy_params, obs, goal, key, cfg)[0]


# --------------------------------------------------------------------------- init

def _optimizers(cfg: SACConfig):
    return optax.adam(cfg.policy_lr), optax.adam(cfg.q_lr), optax.adam(cfg.alpha_lr)


def init_sac(key, obs_dim: int, goal_dim: int, action_dim: int, cfg: SACConfig) -> SACState:
    kp, kq = jax.random.split(key)
    obs, goal = jnp.zeros((1, obs_dim)), jnp.zeros((1, goal_dim))
    policy_params = MLP(cfg.hidden, 2 * action_dim, 1e-3).init(kp, jnp.concatenate([obs, goal], -1))
    q_params = TwinQ(cfg.hidden).init(kq, obs, goal, jnp.zeros((1, action_dim)))
    log_alpha = jnp.asarray(cfg.init_log_alpha, jnp.float32)
    popt, qopt, aopt = _optimizers(cfg)
    return SACState(
        policy_params=policy_params,
        q_params=q_params,
        target_q_params=jax.tree.map(jnp.copy, q_params),
        log_alpha=log_alpha,
        policy_opt_state=popt.init(policy_params),
        q_opt_state=qopt.init(q_params),
        alpha_opt_state=aopt.init(log_alpha),
        step=jnp.zeros((), jnp.int32),
    )


# --------------------------------------------------------------------------- losses

def critic_loss(q_params, target_q_params, policy_params, alpha, batch: Transition, key,
                cfg: SACConfig):
    """Sum of the two Q MSEs to y = s r + (1 - done) gamma (min Q'(s', a') - alpha log pi(a'|s'))."""
    next_a, next_logp = sample_action(policy_params, batch.next_obs, batch.goal, key, cfg)
    target_q = jnp.min(q_values(target_q_params, batch.next_obs, batch.goal, next_a), axis=0)
    target_v = target_q - alpha * next_logp
    y = cfg.reward_scale * batch.reward + (1.0 - batch.done) * cfg.discount * target_v
    y = jax.lax.stop_gradient(y)
    q = q_values(q_params, batch.obs, batch.goal, batch.action)
    loss = jnp.sum(jnp.mean(jnp.square(q - y[None]), axis=-1))
    return loss, {"q_mean": jnp.mean(q), "q_target_mean": jnp.mean(y)}


def actor_loss(policy_params, q_params, alpha, batch: Transition, key, cfg: SACConfig):
    """mean(alpha log pi(a|s) - min Q(s, a)), a ~ pi reparameterized; aux has log_prob, entropy."""
    a, logp = sample_action(policy_params, batch.obs, batch.goal, key, cfg)
    q = jnp.min(q_values(q_params, batch.obs, batch.goal, a), axis=0)
    loss = jnp.mean(alpha * logp - q)
    return loss, {"log_prob": logp, "entropy": -jnp.mean(logp)}


def alpha_loss(log_alpha, log_prob, target_entropy: float):
    """rlkit's -mean(log_alpha (log pi + target_entropy)): alpha falls when entropy > target."""
    return -jnp.mean(log_alpha * jax.lax.stop_gradient(log_prob + target_entropy))


# --------------------------------------------------------------------------- update

def sac_update(state: SACState, key, batch: Transition, cfg: SACConfig):
    """One SAC step on `batch`: critic, actor and alpha from the same parameters, then targets.

    Returns (state, metrics); metrics["finite"] is False when a loss or gradient is NaN/inf
    (the training loop stops on it).
    """
    k_critic, k_actor = jax.random.split(key)
    popt, qopt, aopt = _optimizers(cfg)
    alpha = jnp.exp(state.log_alpha)

    (q_loss, q_aux), q_grads = jax.value_and_grad(critic_loss, has_aux=True)(
        state.q_params, state.target_q_params, state.policy_params, alpha, batch, k_critic, cfg)
    (pi_loss, pi_aux), pi_grads = jax.value_and_grad(actor_loss, has_aux=True)(
        state.policy_params, state.q_params, alpha, batch, k_actor, cfg)
    target_entropy = cfg.entropy_target(batch.action.shape[-1])
    a_loss, a_grad = jax.value_and_grad(alpha_loss)(state.log_alpha, pi_aux["log_prob"], target_entropy)

    q_upd, q_opt_state = qopt.update(q_grads, state.q_opt_state, state.q_params)
    q_params = optax.apply_updates(state.q_params, q_upd)
    pi_upd, pi_opt_state = popt.update(pi_grads, state.policy_opt_state, state.policy_params)
    policy_params = optax.apply_updates(state.policy_params, pi_upd)
    a_upd, a_opt_state = aopt.update(a_grad, state.alpha_opt_state, state.log_alpha)
    log_alpha = optax.apply_updates(state.log_alpha, a_upd)

    # Soft target update every `target_update_period` updates (Table 4: every update).
    step = state.step + 1
    tau = jnp.where(step % cfg.target_update_period == 0, cfg.tau, 0.0)
    target_q_params = optax.incremental_update(q_params, state.target_q_params, tau)

    q_gnorm, pi_gnorm = optax.tree.norm(q_grads), optax.tree.norm(pi_grads)
    finite = jnp.all(jnp.isfinite(jnp.stack([q_loss, pi_loss, a_loss, q_gnorm, pi_gnorm])))
    metrics = {
        "q_loss": q_loss,
        "policy_loss": pi_loss,
        "alpha": alpha,
        "alpha_loss": a_loss,
        "q_mean": q_aux["q_mean"],
        "q_target_mean": q_aux["q_target_mean"],
        "entropy": pi_aux["entropy"],
        "q_grad_norm": q_gnorm,
        "policy_grad_norm": pi_gnorm,
        "finite": finite,
    }
    new_state = state.replace(
        policy_params=policy_params, q_params=q_params, target_q_params=target_q_params,
        log_alpha=log_alpha, policy_opt_state=pi_opt_state, q_opt_state=q_opt_state,
        alpha_opt_state=a_opt_state, step=step)
    return new_state, metrics
