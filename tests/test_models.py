"""Encoder networks (roll_jax.encoders.models) and their configs (configs.encoders)."""

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from configs.encoders import (
    TASKS,
    LSTMConfig,
    VAEConfig,
    lstm_config,
    object_vae_config,
    scene_vae_config,
)
from roll_jax.encoders import models, steps
from roll_jax.encoders.models import (
    LSTMEncoder,
    check_images,
    init_lstm_params,
    lstm_encode,
    lstm_step,
    to_float,
)

# --- configs ------------------------------------------------------------------------------------

def test_scene_vae_config_matches_paper_table():
    # Table 2 columns: puck_push, hurdle_bottom, hurdle_top, door_open, pickup.
    beta = dict(zip(TASKS, (20, 20, 20, 20, 30)))
    roll_latent = dict(zip(TASKS, (6, 6, 6, 16, 16)))
    skewfit_latent = dict(zip(TASKS, (4, 6, 6, 16, 16)))
    for task in TASKS:
        roll = scene_vae_config(task)
        skew = scene_vae_config(task, algo="skewfit")
        assert (roll.beta, roll.latent_dim) == (beta[task], roll_latent[task])
        assert (skew.beta, skew.latent_dim) == (beta[task], skewfit_latent[task])
        assert roll.batch_size == skew.batch_size == 64  # Table 3
        assert roll.feature_dim == 576 and roll.matching_coef == 0.0
        assert (roll.lr, roll.epochs, roll.batches_per_epoch) == (1e-3, 2000, 25)


def test_object_vae_and_lstm_config_match_paper_table():
    coef = dict(zip(TASKS, (400, 400, 800, 50, 50)))  # Table 2
    for task in TASKS:
        obj = object_vae_config(task)
        assert obj.matching_coef == coef[task]
        assert (obj.latent_dim, obj.beta, obj.batch_size, obj.feature_dim) == (6, 20, 128, 6)
        assert obj.occlusion_drop == 0.5 and obj.image_size == 48
        lstm = lstm_config(task)
        assert (lstm.hidden, lstm.layers, lstm.matching_coef, lstm.lr) == (128, 2, 50, 1e-3)
        assert lstm.out_dim == obj.latent_dim
    assert lstm_config("puck_push").online_batches(0) == (500, 80)
    assert lstm_config("puck_push").online_batches(20_000) == (500, 20)
    assert lstm_config("puck_push").online_batches(60_000) == (1000, 20)


def test_config_errors_name_the_problem():
    for fn in (scene_vae_config, object_vae_config, lstm_config):
        with pytest.raises(ValueError, match="push_puck"):
            fn("push_puck")
    with pytest.raises(ValueError, match="rig"):
        scene_vae_config("puck_push", algo="rig")
    with pytest.raises(ValueError, match=r"latent_dim.*-1"):
        VAEConfig(latent_dim=-1, beta=1.0, feature_dim=6)
    with pytest.raises(ValueError, match=r"batch_size.*0"):
        object_vae_config("pickup", batch_size=0)
    with pytest.raises(ValueError, match=r"hidden.*0"):
        LSTMConfig(hidden=0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        lstm_config("pickup").hidden = 3


# --- ConvVAE ------------------------------------------------------------------------------------

def test_conv_vae_shapes_scene_and_object():
    key = jax.random.key(0)
    x = jnp.zeros((2, 48, 48, 3), jnp.uint8)
    for cfg in (scene_vae_config("door_open"), object_vae_config("puck_push")):
        model = models.vae_model(cfg)
        params = jax.eval_shape(model.init, key, x, key)  # shapes only: no compile
        assert params["params"]["feature"]["kernel"].shape == (3 * 3 * 64, cfg.feature_dim)
        recon, mean, logvar = jax.eval_shape(model.apply, params, x, key)
        assert recon.shape == (2, 48, 48, 3)
        assert mean.shape == logvar.shape == (2, cfg.latent_dim)


def test_conv_vae_runs_in_range_with_leading_dims():
    cfg = object_vae_config("hurdle_top")
    state = steps.init_vae(jax.random.key(0), cfg)
    model = models.vae_model(cfg)
    x = jax.random.randint(jax.random.key(1), (2, 3, 48, 48, 3), 0, 256).astype(jnp.uint8)

    @jax.jit  # one compile for the whole check
    def run(params, x, key):
        recon, mean, logvar = model.apply(params, x, key)
        return (recon, mean, logvar, models.encode_mean(params, cfg, x),
                models.decode(params, cfg, mean))

    recon, mean, logvar, enc_mean, dec = run(state.params, x, jax.random.key(2))
    assert recon.shape == dec.shape == (2, 3, 48, 48, 3) and mean.shape == (2, 3, 6)
    assert float(dec.min()) >= 0.0 and float(dec.max()) <= 1.0
    assert bool(jnp.all(jnp.isfinite(recon)))
    assert bool(jnp.all(logvar >= np.log(cfg.min_variance) - 1e-5))
    np.testing.assert_allclose(enc_mean, mean, atol=1e-5)


def test_image_checks():
    assert to_float(jnp.full((48, 48, 3), 255, jnp.uint8)).max() == 1.0
    assert to_float(jnp.zeros((48, 48, 3), jnp.uint8)).dtype == jnp.float32
    with pytest.raises(ValueError, match="48, 48, 3"):
        check_images(jnp.zeros((2, 64, 64, 3), jnp.uint8))
    with pytest.raises(ValueError, match="int32"):
        check_images(jnp.zeros((2, 48, 48, 3), jnp.int32))
    cfg = object_vae_config("pickup", batch_size=2)
    state = jax.eval_shape(functools.partial(steps.init_vae, cfg=cfg), jax.random.key(0))
    with pytest.raises(ValueError, match="shape"):
        steps.vae_train_step(state, jax.random.key(0), jnp.zeros((2, 48, 48), jnp.uint8), cfg)
    with pytest.raises(ValueError, match="object_masks"):
        steps.vae_train_step(state, jax.random.key(0), jnp.zeros((2, 48, 48, 3), jnp.uint8),
                                cfg, object_masks=jnp.zeros((2, 48, 48, 3), bool))
    # Arm-pair partners come with arm_pair_coef > 0, in the images' shape.
    images = jnp.zeros((2, 48, 48, 3), jnp.uint8)
    with pytest.raises(ValueError, match="partner images go with arm_pair_coef > 0"):
        steps.vae_train_step(state, jax.random.key(0), images, cfg, partners=images)
    paired = dataclasses.replace(cfg, arm_pair_coef=1.0)
    with pytest.raises(ValueError, match="partner images go with arm_pair_coef > 0"):
        steps.vae_train_step(state, jax.random.key(0), images, paired)
    with pytest.raises(ValueError, match=r"partners must have the images' shape \(2, 48, 48, 3\)"):
        steps.vae_train_step(state, jax.random.key(0), images, paired, partners=images[:1])
    with pytest.raises(ValueError, match="arm_pair_coef must be >= 0, got -1.0"):
        object_vae_config("pickup", arm_pair_coef=-1.0)


# --- LSTM ---------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def lstm():
    model = LSTMEncoder(hidden=16, layers=2, out_dim=3)
    params = jax.jit(init_lstm_params, static_argnums=(1, 2))(jax.random.key(0), model, 4)
    return model, params


def test_lstm_shapes(lstm):
    model, params = lstm
    seq = jax.random.normal(jax.random.key(1), (5, 4))
    assert lstm_encode(params, seq, model=model).shape == (5, 3)
    assert lstm_encode(params, jnp.stack([seq, seq]), model=model).shape == (2, 5, 3)
    assert LSTMEncoder.from_params(params) == model
    cfg = lstm_config("puck_push")
    state = jax.eval_shape(functools.partial(steps.init_lstm, cfg=cfg, in_dim=6),
                           jax.random.key(0))
    assert jax.eval_shape(lstm_encode, state.params, jnp.zeros((7, 6))).shape == (7, cfg.out_dim)


def test_lstm_init_vmaps_over_seeds():
    # Seeds are a vmapped axis of the train state: seed i of a batch must equal seed i alone.
    # (Regression: flax's orthogonal LSTM init deadlocked XLA:CPU under jit(vmap).)
    cfg = lstm_config("pickup")
    keys = jax.random.split(jax.random.key(0), 2)
    batched = jax.jit(jax.vmap(lambda k: steps.init_lstm(k, cfg, 6)))(keys)
    single = steps.init_lstm(keys[1], cfg, 6)
    for a, b in zip(jax.tree.leaves(batched), jax.tree.leaves(single)):
        np.testing.assert_array_equal(a[1], b)


def test_lstm_resets_match_python_loop(lstm):
    model, params = lstm
    seq = jax.random.normal(jax.random.key(2), (8, 4))
    resets = jnp.zeros(8, bool).at[0].set(True).at[3].set(True)
    encode = jax.jit(lstm_encode, static_argnames="model")
    scanned = encode(params, seq, resets, model=model)

    # Plain loop: the carry is zeroed by hand at every episode start.
    carry, outs = model.zero_carry(), []
    for t in range(8):
        if bool(resets[t]):
            carry = jax.tree.map(jnp.zeros_like, carry)
        carry, z = model.apply(params, carry, seq[t])
        outs.append(z)
    np.testing.assert_allclose(scanned, jnp.stack(outs), atol=1e-5)

    # After the reset the second episode is encoded as if it were a sequence of its own ...
    fresh = encode(params, jnp.roll(seq, -3, axis=0), jnp.zeros(8, bool), model=model)
    np.testing.assert_allclose(scanned[3:], fresh[:5], atol=1e-5)
    # ... and without the reset the history leaks into it.
    no_reset = encode(params, seq, jnp.zeros(8, bool), model=model)
    assert float(jnp.abs(no_reset[3:] - scanned[3:]).max()) > 1e-4

    # Online stepping with lstm_step gives the same encodings.
    carry, outs = model.zero_carry(), []
    for t in range(8):
        carry, z = lstm_step(params, carry, seq[t], resets[t], model=model)
        outs.append(z)
    np.testing.assert_allclose(scanned, jnp.stack(outs), atol=1e-5)
