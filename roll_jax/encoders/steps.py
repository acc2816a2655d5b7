"""Train states and pure training steps for the VAEs and the object LSTM.

Every function is pure and jit-compatible with the config static (configs are frozen, hashable
dataclasses): `jax.jit(vae_train_step, static_argnames="cfg")` etc. Shape/dtype errors are
raised at trace time, i.e. before anything runs. One optax chain per parameter group: the
optimizer is rebuilt from the config inside each step (it is stateless; only `opt_state`
lives in the train state).

Training scheme ("Robustness to Object Occlusions", "Training schedules"): the scene-VAE uses
the plain beta-VAE loss; the object-VAE adds the VAE matching loss on a copy of each segmented
image with 50% of its object pixels dropped; the LSTM is pre-trained with the auto-encoder
loss only (`lstm_train_step(..., occlusion=None)`) and trained online with auto-encoder +
matching loss, the occluded frame coming from `make_occlusion`.
"""

from __future__ import annotations

import functools
from typing import Any

import flax.struct
import jax
import jax.numpy as jnp
import optax

from configs.encoders import LSTMConfig, VAEConfig
from roll_jax.encoders import losses
from roll_jax.encoders.models import (
    ConvVAE,
    LSTMEncoder,
    check_images,
    encode_mean,
    init_lstm_params,
    lstm_model,
    vae_model,
)


@flax.struct.dataclass
class ModelState:
    """A trained model (VAE or LSTM): parameters, Adam state, steps taken."""

    params: Any
    opt_state: Any
    step: jax.Array


@flax.struct.dataclass
class Occlusion:
    """One synthetically occluded frame per trajectory: index t [B] and its VAE mean [B, d]."""

    t: jax.Array
    latent: jax.Array


def vae_optimizer(cfg: VAEConfig) -> optax.GradientTransformation:
    return _adam(cfg.lr)


def lstm_optimizer(cfg: LSTMConfig) -> optax.GradientTransformation:
    return _adam(cfg.lr)


def _adam(lr: float) -> optax.GradientTransformation:
    return optax.adam(lr)  # lr: "Training schedules"; Adam: reference code (rlkit)


# --- VAE --------------------------------------------------------------------------------------

# Jitted on the module (not the config), so configs that differ only in loss weights or
# schedules share one compiled init; the whole state in one jit because op-by-op init costs a
# compile per parameter shape. (Threefry keys are kept although XLA's "rbg" generator compiles
# this init ~3x faster on CPU: rbg gives other parameters under vmap and across backends, so
# seed i of a vmapped run would not equal the same seed run alone.)
@functools.partial(jax.jit, static_argnums=(1, 2, 3))
def _init_vae(key: jax.Array, model: ConvVAE, image_shape: tuple[int, ...], lr: float) -> ModelState:
    params = model.init(key, jnp.zeros((1,) + image_shape, jnp.uint8), key)
    return ModelState(params=params, opt_state=_adam(lr).init(params), step=jnp.zeros((), jnp.int32))


def init_vae(key: jax.Array, cfg: VAEConfig) -> ModelState:
    return _init_vae(key, vae_model(cfg), cfg.image_shape, cfg.lr)


def _check_masks(masks, images) -> None:
    if masks is not None and tuple(masks.shape) != tuple(images.shape[:-1]):
        raise ValueError(f"object_masks must have shape {tuple(images.shape[:-1])} "
                         f"(images without channels), got {tuple(masks.shape)}")


def grad_in_parts(loss_fn, params: Any, batch: Any, parts: int) -> tuple[Any, dict]:
    """`jax.grad(loss_fn, has_aux=True)(params, batch)` for a loss and metrics that are means
    over the leading axis of every leaf of `batch`, as the mean over `parts` equal slices of
    it: the same values within float32 roundoff, and no op of one slice waits for the
    other's, so XLA:CPU runs them side by side on its threads."""
    if parts == 1:
        return jax.grad(loss_fn, has_aux=True)(params, batch)
    n = jax.tree.leaves(batch)[0].shape[0]
    if n % parts:
        raise ValueError(f"a batch of {n} does not split into grad_parts={parts} equal slices")
    size = n // parts
    per_part = [jax.grad(loss_fn, has_aux=True)(
        params, jax.tree.map(lambda x, i=i: x[i * size:(i + 1) * size], batch))
        for i in range(parts)]
    return jax.tree.map(lambda *xs: functools.reduce(jnp.add, xs) / parts, *per_part)


def grad_parts(cfg: VAEConfig, batch: int) -> int:
    """`cfg.grad_parts`, or for None (auto) 2 on a CPU backend when `batch` is even, else 1."""
    if cfg.grad_parts is not None:
        return cfg.grad_parts
    return 2 if jax.default_backend() == "cpu" and batch % 2 == 0 else 1


def vae_train_step(state: ModelState, key: jax.Array, images: jax.Array, cfg: VAEConfig,
                   object_masks: jax.Array | None = None, partners: jax.Array | None = None
                   ) -> tuple[ModelState, dict]:
    """One Adam step on a batch of images [B, 48, 48, 3] uint8; adds the matching loss on
    synthetically occluded copies when cfg.matching_coef > 0 (object-VAE), and the arm-pair
    matching loss against `partners` (the same object states, the arm elsewhere) when
    cfg.arm_pair_coef > 0."""
    check_images(images)
    _check_masks(object_masks, images)
    if (partners is None) != (cfg.arm_pair_coef == 0):
        raise ValueError(f"partner images go with arm_pair_coef > 0 (got {cfg.arm_pair_coef!r} "
                         f"and {'no ' if partners is None else ''}partners)")
    if partners is not None and partners.shape != images.shape:
        raise ValueError(f"partners must have the images' shape {tuple(images.shape)}, got "
                         f"{tuple(partners.shape)}")
    k_noise, k_occ = jax.random.split(key)
    occluded = None
    if cfg.matching_coef > 0:
        occluded = losses.OCCLUSIONS[cfg.occlusion_shape](k_occ, images, object_masks,
                                                          cfg.occlusion_drop)

    noise = jax.random.normal(k_noise, (images.shape[0], cfg.latent_dim))

    def loss_fn(p, batch):
        x, eps, x_occ, x_pair = batch
        return losses.vae_loss(p, vae_model(cfg), x, eps, cfg.effective_beta,
                               occluded=x_occ, matching_coef=cfg.matching_coef,
                               one_sided=cfg.matching_one_sided,
                               recon_reduction=cfg.recon_reduction,
                               partners=x_pair, pair_coef=cfg.arm_pair_coef)

    grads, metrics = grad_in_parts(loss_fn, state.params, (images, noise, occluded, partners),
                                   grad_parts(cfg, images.shape[0]))
    updates, opt_state = vae_optimizer(cfg).update(grads, state.opt_state, state.params)
    params = optax.apply_updates(state.params, updates)
    return ModelState(params=params, opt_state=opt_state, step=state.step + 1), metrics


def vae_fit_epoch(state: ModelState, key: jax.Array, dataset: jax.Array, cfg: VAEConfig,
                  object_masks: jax.Array | None = None, partners: jax.Array | None = None
                  ) -> tuple[ModelState, dict]:
    """cfg.batches_per_epoch steps on minibatches of cfg.batch_size drawn uniformly (with
    replacement, as rlkit does) from dataset [N, 48, 48, 3] (and the same rows of `partners`,
    `vae_train_step`'s); one lax.scan. Returns the per-batch metrics stacked
    [batches_per_epoch]."""
    check_images(dataset, "dataset")
    _check_masks(object_masks, dataset)
    n = dataset.shape[0]

    def body(st, k):
        k_idx, k_step = jax.random.split(k)
        idx = jax.random.randint(k_idx, (cfg.batch_size,), 0, n)
        masks = None if object_masks is None else object_masks[idx]
        pairs = None if partners is None else partners[idx]
        return vae_train_step(st, k_step, dataset[idx], cfg, masks, pairs)

    return jax.lax.scan(body, state, jax.random.split(key, cfg.batches_per_epoch))


# --- LSTM -------------------------------------------------------------------------------------

@functools.partial(jax.jit, static_argnums=(1, 2, 3))
def _init_lstm(key: jax.Array, model: LSTMEncoder, in_dim: int, lr: float) -> ModelState:
    params = init_lstm_params(key, model, in_dim)
    return ModelState(params=params, opt_state=_adam(lr).init(params), step=jnp.zeros((), jnp.int32))


def init_lstm(key: jax.Array, cfg: LSTMConfig, in_dim: int) -> ModelState:
    return _init_lstm(key, lstm_model(cfg), in_dim, cfg.lr)


def occlusion_frames(key: jax.Array, images: jax.Array, object_masks: jax.Array | None,
                     min_t: int, drop: float) -> tuple[jax.Array, jax.Array]:
    """Pick t in [min_t, T) per trajectory of images [B, T, 48, 48, 3] and drop `drop` of
    frame t's object pixels (`object_masks` [B, T, 48, 48], or None: the non-zero pixels).
    Returns (t [B], occluded frames [B, 48, 48, 3])."""
    check_images(images)
    if images.ndim != 5:
        raise ValueError(f"images must be [B, T, 48, 48, 3], got shape {tuple(images.shape)}")
    b, t_len = images.shape[:2]
    if t_len <= min_t:
        raise ValueError(f"trajectories of length {t_len} leave no frame t >= "
                         f"min_occlusion_t={min_t} to occlude")
    _check_masks(object_masks, images)
    k_t, k_occ = jax.random.split(key)
    t = jax.random.randint(k_t, (b,), min_t, t_len)
    frames = images[jnp.arange(b), t]
    masks = None if object_masks is None else object_masks[jnp.arange(b), t]
    return t, losses.occlude(k_occ, frames, masks, drop)


def make_occlusion(key: jax.Array, vae_params: Any, vae_cfg: VAEConfig, images: jax.Array,
                   cfg: LSTMConfig, object_masks: jax.Array | None = None) -> Occlusion:
    """`occlusion_frames` at the LSTM config's `min_occlusion_t` and `occlusion_drop`, the
    occluded frame encoded with the frozen object-VAE."""
    t, occluded = occlusion_frames(key, images, object_masks, cfg.min_occlusion_t,
                                   cfg.occlusion_drop)
    latent = jax.lax.stop_gradient(encode_mean(vae_params, vae_cfg, occluded))
    return Occlusion(t=t, latent=latent)


def lstm_train_step(state: ModelState, key: jax.Array, seq_latents: jax.Array, cfg: LSTMConfig,
                    occlusion: Occlusion | None = None) -> tuple[ModelState, dict]:
    """One Adam step on trajectories of object-VAE means seq_latents [B, T, d]: auto-encoder
    loss, plus cfg.matching_coef * matching loss when an `occlusion` is given. `key` is
    unused (kept for the uniform step signature)."""
    del key
    if seq_latents.ndim != 3:
        raise ValueError(f"seq_latents must be [B, T, d], got shape {tuple(seq_latents.shape)}")
    occ_latent = None if occlusion is None else occlusion.latent
    occ_t = None if occlusion is None else occlusion.t

    def loss_fn(p):
        return losses.lstm_loss(p, lstm_model(cfg), seq_latents, occ_latent, occ_t,
                                matching_coef=cfg.matching_coef, ae_coef=cfg.ae_coef,
                                one_sided=cfg.matching_one_sided)

    grads, metrics = jax.grad(loss_fn, has_aux=True)(state.params)
    updates, opt_state = lstm_optimizer(cfg).update(grads, state.opt_state, state.params)
    params = optax.apply_updates(state.params, updates)
    return ModelState(params=params, opt_state=opt_state, step=state.step + 1), metrics


@flax.struct.dataclass
class OcclusionSource:
    """The segmented images behind a dataset of latent sequences, for the matching loss:
    images [N, T, 48, 48, 3], their object masks [N, T, 48, 48] (or None: the non-zero
    pixels) and the frozen object-VAE that encodes an occluded frame."""

    images: jax.Array
    masks: jax.Array | None
    vae_params: Any
    vae_cfg: VAEConfig = flax.struct.field(pytree_node=False)

    def occlusion(self, key: jax.Array, idx: jax.Array, cfg: LSTMConfig) -> Occlusion:
        """`make_occlusion` of the sequences `idx` [B]."""
        masks = None if self.masks is None else self.masks[idx]
        return make_occlusion(key, self.vae_params, self.vae_cfg, self.images[idx], cfg, masks)


def lstm_fit_epoch(state: ModelState, key: jax.Array, seq_dataset: jax.Array, cfg: LSTMConfig,
                   batches: int | None = None, occlusions: OcclusionSource | None = None
                   ) -> tuple[ModelState, dict]:
    """`batches` (default cfg.batches_per_epoch) steps on minibatches of cfg.batch_size latent
    sequences drawn uniformly (with replacement) from seq_dataset [N, T, d]: the auto-encoder
    loss (pretraining), plus the matching loss on frames hidden by `occlusions` when given
    (the occlusion analysis). One lax.scan; returns the per-batch metrics stacked.

    Each step's key splits into (batch, occlusion, step); with JAX's default partitionable
    threefry the first key is the same as a split in two gives, so the batches do not depend
    on whether the matching loss is on (the occlusion analysis trains an LSTM with and one
    without it on the same batches)."""
    n = seq_dataset.shape[0]

    def body(st, k):
        k_idx, k_occ, k_step = jax.random.split(k, 3)
        idx = jax.random.randint(k_idx, (cfg.batch_size,), 0, n)
        occ = None if occlusions is None else occlusions.occlusion(k_occ, idx, cfg)
        return lstm_train_step(st, k_step, seq_dataset[idx], cfg, occ)

    return jax.lax.scan(body, state, jax.random.split(key, batches or cfg.batches_per_epoch))
