"""Encoder losses ("Using Segmented Images for Reward Computation", "Robustness to Object
Occlusions"), as pure functions of (params, model definition, data).

Conventions: squared norms are summed over latent dimensions (the paper's ||.||_2^2) and
averaged over batch and time. The matching losses are two-sided by default, exactly the
paper's equations (no stop-gradient on either encoding; also the reference code's default);
`one_sided=True` detaches the clean encoding.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp

from roll_jax.encoders.models import ConvVAE, LSTMEncoder, check_images, lstm_encode, to_float


def kl_divergence(mean: jax.Array, logvar: jax.Array) -> jax.Array:
    """KL(N(mean, exp(logvar)) || N(0, I)) summed over the last axis -> [...]."""
    return 0.5 * jnp.sum(jnp.exp(logvar) + jnp.square(mean) - 1.0 - logvar, axis=-1)


def squared_error(recon: jax.Array, images: jax.Array) -> jax.Array:
    """Per-image sum of squared pixel errors (float images in [0, 1]) -> [...]."""
    return jnp.sum(jnp.square(recon - to_float(images)), axis=(-3, -2, -1))


def matching_distance(clean: jax.Array, occluded: jax.Array, one_sided: bool = False) -> jax.Array:
    """||clean - occluded||^2 over the last axis; `one_sided` stops the gradient into `clean`."""
    if one_sided:
        clean = jax.lax.stop_gradient(clean)
    return jnp.sum(jnp.square(clean - occluded), axis=-1)


def occlude(key: jax.Array, images: jax.Array, object_mask: jax.Array | None = None,
            drop_frac: float = 0.5) -> jax.Array:
    """Synthetic occlusion: zero each object pixel independently with probability `drop_frac`.

    images [..., H, W, C] (segmented: non-object pixels are already 0); object_mask [..., H, W]
    bool, default = pixels with any non-zero channel. Same dtype out; an empty image stays empty.
    """
    if object_mask is None:
        object_mask = jnp.any(images != 0, axis=-1)
    drop = jax.random.bernoulli(key, drop_frac, images.shape[:-1]) & object_mask.astype(bool)
    return jnp.where(drop[..., None], jnp.zeros_like(images), images)


def occlude_edge(key: jax.Array, images: jax.Array, object_mask: jax.Array | None = None,
                 drop_frac: float = 0.5) -> jax.Array:
    """Synthetic occlusion by a straight edge, as the arm covers one side of the object: of
    each image's n object pixels, the floor(drop_frac * n) furthest along a random direction
    are zeroed. Arguments and output as `occlude`.
    """
    if object_mask is None:
        object_mask = jnp.any(images != 0, axis=-1)
    mask = object_mask.astype(bool)
    lead, (h, w) = mask.shape[:-2], mask.shape[-2:]
    angle = jax.random.uniform(key, lead, maxval=2.0 * jnp.pi)
    rows, cols = jnp.mgrid[0:h, 0:w]
    along = (jnp.cos(angle)[..., None, None] * cols + jnp.sin(angle)[..., None, None] * rows)
    flat = jnp.where(mask, along, -jnp.inf).reshape(lead + (h * w,))
    n_drop = jnp.floor(drop_frac * mask.sum(axis=(-2, -1))).astype(jnp.int32)
    descending = -jnp.sort(-flat, axis=-1)
    threshold = jnp.take_along_axis(descending, jnp.maximum(n_drop - 1, 0)[..., None], -1)[..., 0]
    drop = mask & (along >= threshold[..., None, None]) & (n_drop > 0)[..., None, None]
    return jnp.where(drop[..., None], jnp.zeros_like(images), images)


OCCLUSIONS = {"pixels": occlude, "edge": occlude_edge}


def vae_matching_loss(params: Any, model: ConvVAE, images: jax.Array, occluded: jax.Array,
                      one_sided: bool = False) -> jax.Array:
    """L^matching(phi^s) = ||f(I^s) - f(I^s,occ)||^2 on the encoder means, batch mean."""
    m_clean, _ = model.apply(params, images, method=ConvVAE.encode)
    m_occ, _ = model.apply(params, occluded, method=ConvVAE.encode)
    return jnp.mean(matching_distance(m_clean, m_occ, one_sided))


def vae_loss(params: Any, model: ConvVAE, images: jax.Array, noise: jax.Array, beta: float,
             occluded: jax.Array | None = None, matching_coef: float = 0.0,
             one_sided: bool = False, recon_reduction: str = "sum",
             partners: jax.Array | None = None, pair_coef: float = 0.0
             ) -> tuple[jax.Array, dict]:
    """beta-VAE loss: squared error (Gaussian identity-variance NLL up to a constant) + beta KL,
    batch mean; plus matching_coef * L^matching when `occluded` images are given, and
    pair_coef * the batch mean of ||mu(images) - mu(partners)||^2 when `partners` (the same
    object states, the arm elsewhere) are. `noise` [B, latent_dim]: the standard normal draws
    of the reparameterisation z = mean + std * noise.

    recon_reduction "sum" sums the squared error over pixels (the log-likelihood); "mean"
    averages it (reference-code scale).
    """
    check_images(images)
    mean, logvar = model.apply(params, images, method=ConvVAE.encode)
    if noise.shape != mean.shape:
        raise ValueError(f"noise must have the latent means' shape {tuple(mean.shape)}, got "
                         f"{tuple(noise.shape)}")
    z = mean + jnp.exp(0.5 * logvar) * noise
    recon = model.apply(params, z, method=ConvVAE.decode)
    sse = squared_error(recon, images)
    n_pix = images.shape[-1] * images.shape[-2] * images.shape[-3]
    rec = jnp.mean(sse) if recon_reduction == "sum" else jnp.mean(sse) / n_pix
    kl = jnp.mean(kl_divergence(mean, logvar))
    loss = rec + beta * kl
    metrics = {"recon": rec, "mse": jnp.mean(sse) / n_pix, "kl": kl}
    if occluded is not None:
        check_images(occluded, "occluded")
        m_occ, _ = model.apply(params, occluded, method=ConvVAE.encode)
        match = jnp.mean(matching_distance(mean, m_occ, one_sided))
        loss = loss + matching_coef * match
        metrics["matching"] = match
    if partners is not None:
        check_images(partners, "partners")
        m_pair, _ = model.apply(params, partners, method=ConvVAE.encode)
        pair = jnp.mean(matching_distance(mean, m_pair))
        loss = loss + pair_coef * pair
        metrics["pair"] = pair
    metrics["loss"] = loss
    return loss, metrics


def insert_occlusion(latents: jax.Array, occ_latent: jax.Array, occ_t: jax.Array) -> jax.Array:
    """Replace frame occ_t[b] of latents [B, T, d] by occ_latent[b] -> the occluded sequence."""
    t_idx = jnp.arange(latents.shape[1])
    hit = (t_idx[None, :] == occ_t[:, None])[..., None]
    return jnp.where(hit, occ_latent[:, None, :], latents)


def lstm_loss(params: Any, model: LSTMEncoder, latents: jax.Array,
              occ_latent: jax.Array | None = None, occ_t: jax.Array | None = None,
              matching_coef: float = 0.0, ae_coef: float = 1.0,
              one_sided: bool = False) -> tuple[jax.Array, dict]:
    """ae_coef * L^ae + matching_coef * L^matching(psi) on trajectories of object latents.

    latents [B, T, d]: object-VAE means of the clean trajectories (one episode each; the
    VAE is frozen, so they are constants). L^ae = mean_t ||z_t - zhat_t||^2. For matching,
    frame occ_t[b] (0-based, >= 1) is replaced by occ_latent[b] (the VAE mean of the occluded
    image) and L^matching = 1/(T-t+1) sum_{i>=t} ||z_i - z*_i||^2, averaged over the batch.
    """
    if latents.ndim != 3:
        raise ValueError(f"latents must be [B, T, d], got shape {latents.shape}")
    latents = jax.lax.stop_gradient(latents.astype(jnp.float32))
    if occ_latent is None:
        z = lstm_encode(params, latents, model=model)
    else:
        occ_seq = insert_occlusion(latents, jax.lax.stop_gradient(occ_latent), occ_t)
        # Clean and occluded sequences through one scan: the LSTM's steps are sequential and
        # small, so on a CPU a step's cost barely depends on the batch (docs/encoders.md,
        # "Losses").
        z, z_occ = jnp.split(lstm_encode(params, jnp.concatenate([latents, occ_seq]),
                                         model=model), 2)
    ae = jnp.mean(jnp.sum(jnp.square(z - latents), axis=-1))
    loss = ae_coef * ae
    metrics = {"ae": ae}
    if occ_latent is not None:
        window = (jnp.arange(latents.shape[1])[None, :] >= occ_t[:, None]).astype(jnp.float32)
        per_step = matching_distance(z, z_occ, one_sided)  # [B, T]
        match = jnp.mean(jnp.sum(per_step * window, 1) / jnp.maximum(jnp.sum(window, 1), 1.0))
        loss = loss + matching_coef * match
        metrics["matching"] = match
    metrics["loss"] = loss
    return loss, metrics
