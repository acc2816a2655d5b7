"""Skew-Fit's estimator and sampling: log p(x) of stored frames under the scene-VAE, the
weights p(x)^alpha, and the one sampler of frames (inverse CDF) that the online scene-VAE
batches and Skew-Fit's goals draw from (Skew-Fit appendix C; rlkit's `compute_p_x_np_to_np`,
`custom_goal_sampler`)."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp

from configs.train import TrainConfig
from roll_jax.agents import replay
from roll_jax.encoders import models
from roll_jax.encoders.models import ConvVAE, to_float


# The per-pixel variance of rlkit's "gaussian_identity_variance" decoder as its estimator uses
# it: decode returns (clamped mean, ones) as (mean, log-variance), and compute_log_p_log_q_log_d
# exponentiates the ones (rlkit vae_trainer.py; the same in ROLL/LSTM_trainer.py).
REFERENCE_DECODER_VARIANCE = math.e


def log_likelihood(cfg: TrainConfig, params, images, key):
    """Skew-Fit's estimate of log p(x) under the scene-VAE, as rlkit computes it
    (compute_p_x_np_to_np, importance sampling with cfg.skew_num_latents samples of q(z|x)):
    the MEAN over the samples of log p(z) - log q(z|x) + log d(x|z), with d Gaussian around
    the decoder mean clamped to [0, 1] with variance e per pixel
    (`REFERENCE_DECODER_VARIANCE`). Terms equal for every image are dropped (the skew weights
    are normalised). The variance sets how sharply p(x)^alpha skews: with variance 1 the
    weights are e times sharper in log space."""
    model = models.vae_model(cfg.scene)
    mean, logvar = model.apply(params, images, method=ConvVAE.encode)
    eps = jax.random.normal(key, (cfg.skew_num_latents,) + mean.shape)
    z = mean + jnp.exp(0.5 * logvar) * eps  # [K, B, d]
    recon = jnp.clip(model.apply(params, z, method=ConvVAE.decode), 0.0, 1.0)
    x = to_float(images)
    log_d = -0.5 * jnp.sum(jnp.square(recon - x), axis=(-3, -2, -1)) / REFERENCE_DECODER_VARIANCE
    log_pz = -0.5 * jnp.sum(jnp.square(z), -1)
    log_qz = -0.5 * jnp.sum(jnp.square(eps) + logvar, -1)
    return jnp.mean(log_d + log_pz - log_qz, axis=0)


def frame_log_p(cfg: TrainConfig, params, images, key, batch_size: int = 256):
    """`log_likelihood` of every image [..., H, W, 3] -> [...], one key per image, batched."""
    lead = images.shape[:-3]
    flat = images.reshape((-1,) + images.shape[-3:])
    n = flat.shape[0]
    keys = jax.random.split(key, n)
    log_p = jax.lax.map(lambda xk: log_likelihood(cfg, params, xk[0][None], xk[1])[0],
                        (flat, keys), batch_size=min(batch_size, n))
    return log_p.reshape(lead)


def skew_weights(log_p, alpha: float, valid):
    """Skew-Fit sampling weights p(x)^alpha over the buffer, normalised (log-space; invalid
    slots get 0, all zeros when no slot is valid)."""
    logw = jnp.where(valid, alpha * log_p, -jnp.inf)
    w = jax.nn.softmax(logw.reshape(-1)).reshape(log_p.shape)
    return jnp.where(valid, w, 0.0)  # softmax of all -inf is NaN


def filled_frames(log_p, size):
    """bool [N, T+1]: frames of the first `size` trajectory slots (the filled ones)."""
    n, t1 = log_p.shape
    return jnp.broadcast_to((jnp.arange(n) < size)[:, None], (n, t1))


def weights_cdf(weights, size):
    """Cumulative weights [N, T+1] over the flattened frames [N * (T+1)] of the first `size`
    trajectory slots (unfilled slots get none): the table `sample_frames` draws from."""
    w = jnp.where(filled_frames(weights, size), jnp.asarray(weights, jnp.float32), 0.0)
    return jnp.cumsum(w.reshape(-1))


def skew_cdf(log_p, alpha: float, size):
    """`weights_cdf` of the Skew-Fit weights (all zeros for an empty buffer): built once per
    phase so each draw is a binary search, not a categorical over the whole buffer."""
    return weights_cdf(skew_weights(log_p, alpha, filled_frames(log_p, size)), size)


def skew_cdf_at(cfg: TrainConfig, log_p, size, epoch):
    """`skew_cdf` of epoch `epoch` (traced int): uniform over the filled frames (alpha 0) up to
    cfg.skew_start_epoch, p(x)^cfg.skew_alpha after it (rlkit's start_skew_epoch). While the
    buffer is small and the VAE young, alpha -1 would put most weight on a few frames."""
    alpha = jnp.where(epoch > cfg.skew_start_epoch, cfg.skew_alpha, 0.0)
    return skew_cdf(log_p, alpha, size)


def sample_frames(key, cdf, n: int):
    """n flat frame indices drawn with probability cdf[i] - cdf[i-1] (inverse CDF)."""
    u = jax.random.uniform(key, (n,)) * cdf[-1]
    # side="right": a zero-weight frame (cdf[i] == cdf[i-1]) is never hit.
    return jnp.minimum(jnp.searchsorted(cdf, u, side="right"), cdf.shape[0] - 1)


def sample_images(buffer: replay.ReplayBuffer, key, n: int, cdf=None):
    """n stored scene images uint8 [n, H, W, 3] drawn from `cdf` (`skew_cdf`, `weights_cdf`),
    or uniformly over the filled frames when None."""
    if cdf is None:
        cdf = weights_cdf(jnp.ones(buffer.images.shape[:2], jnp.float32), buffer.size)
    flat = sample_frames(key, cdf, n)
    t1 = buffer.images.shape[1]
    return buffer.images[flat // t1, flat % t1]
