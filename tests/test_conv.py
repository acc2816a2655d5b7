"""roll_jax/common/conv.py against flax's nn.Conv / nn.ConvTranspose: values and gradients."""
import dataclasses

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from configs.encoders import DECODERS, scene_vae_config
from roll_jax.common import conv
from roll_jax.encoders import models, steps

# (input size, in channels, out channels, kernel, stride)
# The ConvVAE's layers, plus a kernel smaller than its stride for the transposed conv (where
# lax's VALID output is (H-1)*s + max(k, s)).
CONVS = [(48, 3, 16, 5, 3), (15, 16, 32, 3, 2), (7, 32, 64, 3, 2)]
DECONVS = [(3, 64, 32, 3, 2), (7, 32, 16, 3, 2), (15, 16, 3, 6, 3), (4, 2, 3, 2, 3)]


def _normal(seed, shape):
    """Standard-normal float32 test data from numpy: a jax.random draw compiles a program per
    shape (about 1.5 s each here, most of this file's compile time)."""
    return np.random.default_rng(seed).standard_normal(shape, dtype=np.float32)


def _compare(ref, new, x):
    shapes = jax.eval_shape(ref.init, jax.random.PRNGKey(1), x)
    # random biases too: flax initialises them to zero
    params = jax.tree.map(lambda p: _normal(2, p.shape), shapes)
    cot = _normal(3, jax.eval_shape(ref.apply, params, x).shape)

    @jax.jit
    def values_and_grads(p, x):  # one compiled program per module: eager dispatch is slow
        return (ref.apply(p, x), new.apply(p, x),
                jax.grad(lambda p, x: jnp.vdot(ref.apply(p, x), cot), argnums=(0, 1))(p, x),
                jax.grad(lambda p, x: jnp.vdot(new.apply(p, x), cot), argnums=(0, 1))(p, x))

    y_ref, y_new, g_ref, g_new = values_and_grads(params, x)
    assert y_ref.shape == y_new.shape
    np.testing.assert_allclose(y_new, y_ref, rtol=1e-5, atol=1e-5)
    for g_new, g_ref in zip(jax.tree.leaves(g_new), jax.tree.leaves(g_ref)):
        np.testing.assert_allclose(g_new, g_ref, rtol=1e-4, atol=1e-4)


@pytest.mark.parametrize("h,cin,cout,k,s", CONVS)
def test_conv_matches_flax(h, cin, cout, k, s):
    x = _normal(0, (3, h, h + 1, cin))
    _compare(nn.Conv(cout, (k, k), strides=(s, s), padding="VALID"), conv.Conv(cout, k, s), x)


@pytest.mark.parametrize("method", ["patches", "col2im"])
@pytest.mark.parametrize("h,cin,cout,k,s", DECONVS)
def test_conv_transpose_matches_flax(h, cin, cout, k, s, method):
    x = _normal(0, (3, h, h + 2, cin))
    _compare(nn.ConvTranspose(cout, (k, k), strides=(s, s), padding="VALID"),
             conv.ConvTranspose(cout, k, s, method), x)


@pytest.mark.parametrize("decoder", ["deconv", "broadcast"])
def test_vae_impls_share_parameters_and_values(decoder):
    fast = scene_vae_config("puck_push", decoder=decoder)
    state = steps.init_vae(jax.random.PRNGKey(0), fast)
    images = np.random.default_rng(4).integers(0, 256, (4, 48, 48, 3), dtype=np.uint8)
    z = _normal(5, (4, fast.latent_dim))
    for impl in ("lax", "matmul_patches"):
        other = dataclasses.replace(fast, conv_impl=impl)
        assert (jax.tree.structure(state.params)
                == jax.tree.structure(steps.init_vae(jax.random.PRNGKey(0), other).params))
        np.testing.assert_allclose(models.encode_mean(state.params, fast, images),
                                   models.encode_mean(state.params, other, images),
                                   rtol=1e-5, atol=1e-6)
        np.testing.assert_allclose(models.decode(state.params, fast, z),
                                   models.decode(state.params, other, z), rtol=1e-5, atol=1e-5)


def test_broadcast_grid_tiles_the_latent_beside_its_coordinates():
    z = _normal(6, (2, 3))
    g = np.asarray(models.broadcast_grid(jnp.asarray(z), 5))
    assert g.shape == (2, 5, 5, 5)
    np.testing.assert_array_equal(g[:, :, :, :3], np.broadcast_to(z[:, None, None], (2, 5, 5, 3)))
    np.testing.assert_allclose(g[0, 0, :, 3], [-1, -0.5, 0, 0.5, 1])  # x along a row
    np.testing.assert_allclose(g[1, :, 4, 4], [-1, -0.5, 0, 0.5, 1])  # y down a column
    np.testing.assert_array_equal(g[0, :, :, 3], g[0, :, :, 4].T)
    # The decoder has no dense layer of Table 3's: 6 latents + 2 coordinates feed a 3x3 conv.
    cfg = scene_vae_config("puck_push", decoder="broadcast")
    params = steps.init_vae(jax.random.PRNGKey(0), cfg).params["params"]
    assert "dec_fc" not in params
    assert params["broadcast_convs_0"]["kernel"].shape == (3, 3, cfg.latent_dim + 2, 32)
    assert models.DECODERS == DECODERS


def test_bad_conv_impl_and_channels_refused():
    with pytest.raises(ValueError, match="conv_impl"):
        dataclasses.replace(scene_vae_config("puck_push"), conv_impl="fft")
    with pytest.raises(ValueError, match="'mlp'"):
        scene_vae_config("puck_push", decoder="mlp")
    with pytest.raises(ValueError, match="4 channels"):
        conv.conv_valid(jnp.zeros((1, 8, 8, 4)), jnp.zeros((3, 3, 3, 2)), 1)
    with pytest.raises(ValueError, match="4 channels"):
        conv.conv_transpose_col2im(jnp.zeros((1, 8, 8, 4)), jnp.zeros((3, 3, 3, 2)), 2)
    with pytest.raises(ValueError, match="'fft'"):
        conv.ConvTranspose(2, 3, 2, "fft").init(jax.random.PRNGKey(0), jnp.zeros((1, 4, 4, 1)))
