"""Encoder losses (roll_jax.losses) and the training steps built on them (roll_jax.encoders)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from configs.encoders import LSTMConfig, object_vae_config
from roll_jax import encoders, losses
from roll_jax.models import LSTMEncoder, init_lstm_params, lstm_encode


def disc_images(n: int, radius: float = 6.0, background: int = 0) -> jnp.ndarray:
    """n frames [n, 48, 48, 3] uint8 of a reddish disc moving along a circle (a puck-like
    segmented object on black when background=0)."""
    ang = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    cx, cy = 24 + 12 * np.cos(ang), 24 + 12 * np.sin(ang)
    yy, xx = np.mgrid[:48, :48]
    inside = (yy[None] - cy[:, None, None]) ** 2 + (xx[None] - cx[:, None, None]) ** 2 <= radius**2
    img = np.full((n, 48, 48, 3), background, np.uint8)
    img[inside] = (200, 60, 40)
    return jnp.asarray(img)


# One compiled epoch shared by the tests below (the VAE gradient is the slowest compile here).
FIT = jax.jit(encoders.vae_fit_epoch, static_argnames="cfg")


@pytest.fixture(scope="module")
def vae():
    # beta=1, not the paper's 20: for a 6-pixel-radius disc beta=20 makes the collapsed
    # posterior optimal (position costs more nats than the pixels it explains), and this
    # fixture must show that the network and loss *can* learn the object's position.
    cfg = object_vae_config("puck_push", batch_size=8, batches_per_epoch=25, beta=1.0)
    return cfg, encoders.init_vae(jax.random.key(0), cfg)


def test_kl_divergence():
    assert float(losses.kl_divergence(jnp.zeros(4), jnp.zeros(4))) == 0.0
    kl = losses.kl_divergence(jnp.ones((2, 3)), jnp.full((2, 3), np.log(2.0)))
    np.testing.assert_allclose(kl, 3 * 0.5 * (2.0 + 1.0 - 1.0 - np.log(2.0)), rtol=1e-6)


def test_occlude_drops_object_pixels_only():
    img = disc_images(4, radius=10.0)
    obj = jnp.any(img != 0, -1)
    occ = losses.occlude(jax.random.key(0), img, drop_frac=0.5)
    assert occ.dtype == jnp.uint8 and occ.shape == img.shape
    kept = jnp.any(occ != 0, -1)
    frac = float(jnp.sum(obj & ~kept) / jnp.sum(obj))
    assert 0.4 < frac < 0.6
    assert not bool(jnp.any(kept & ~obj))  # background untouched
    assert bool(jnp.all(jnp.where(kept[..., None], occ == img, True)))  # kept pixels unchanged
    np.testing.assert_array_equal(losses.occlude(jax.random.key(0), img, drop_frac=0.0), img)
    assert not bool(jnp.any(losses.occlude(jax.random.key(0), img, drop_frac=1.0)))
    # An explicit mask limits the drop (here: the left half of the image only).
    mask = obj & (jnp.arange(48) < 24)[None, None, :]
    occ = losses.occlude(jax.random.key(1), img, mask, drop_frac=1.0)
    np.testing.assert_array_equal(jnp.any(occ != 0, -1), obj & ~mask)


def test_empty_images_give_finite_losses(vae):
    cfg, state = vae
    empty = jnp.zeros((8, 48, 48, 3), jnp.uint8)
    occ = losses.occlude(jax.random.key(0), empty, drop_frac=0.5)
    assert not bool(jnp.any(occ))
    # A whole epoch of object-VAE steps (with matching loss) on empty segmented images.
    new, metrics = FIT(state, jax.random.key(1), empty, cfg)
    assert all(bool(jnp.all(jnp.isfinite(v))) for v in metrics.values())
    assert float(jnp.max(metrics["matching"])) == 0.0  # occluding nothing changes nothing
    assert all(bool(jnp.all(jnp.isfinite(p))) for p in jax.tree.leaves(new.params))


def test_vae_matching_loss_zero_iff_unoccluded(vae):
    cfg, state = vae
    model = encoders.vae_model(cfg)
    img = disc_images(8)

    @jax.jit
    def match(params, key):
        occ = losses.occlude(key, img, drop_frac=0.5)
        return (losses.vae_matching_loss(params, model, img, img),
                losses.vae_matching_loss(params, model, img, occ),
                losses.vae_matching_loss(params, model, img, occ, one_sided=True))

    same, two_sided, one_sided = match(state.params, jax.random.key(0))
    assert float(same) == 0.0
    assert float(two_sided) > 0.0 and float(one_sided) == float(two_sided)


def test_vae_training_improves_reconstruction(vae):
    cfg, state = vae
    data = disc_images(64)

    @jax.jit
    def recon_mse(params):  # deterministic reconstruction through the mean
        mean = encoders.encode_mean(params, cfg, data)
        return jnp.mean(jnp.square(encoders.decode(params, cfg, mean) - data / 255.0))

    mean_image_mse = float(jnp.mean(jnp.square(data / 255.0 - jnp.mean(data / 255.0, 0))))
    before = float(recon_mse(state.params))
    new, first = FIT(state, jax.random.key(1), data, cfg)
    for epoch in range(3):
        new, last = FIT(new, jax.random.key(2 + epoch), data, cfg)
    after = float(recon_mse(new.params))
    assert int(new.step) == 4 * cfg.batches_per_epoch
    assert first["loss"].shape == (cfg.batches_per_epoch,)
    assert float(last["loss"][-5:].mean()) < 0.6 * float(first["loss"][:5].mean())
    assert float(last["mse"][-5:].mean()) < 0.5 * float(first["mse"][:5].mean())
    # Better than the best latent-free guess (the mean image): the latent encodes the disc.
    assert after < 0.5 * mean_image_mse < before
    assert bool(jnp.all(jnp.isfinite(last["matching"])))


def test_lstm_loss_matches_paper_equation():
    model = LSTMEncoder(hidden=16, layers=2, out_dim=4)
    params = jax.jit(init_lstm_params, static_argnums=(1, 2))(jax.random.key(0), model, 4)
    lat = jax.random.normal(jax.random.key(1), (3, 6, 4))
    t = jnp.array([1, 3, 5])
    occ = jax.random.normal(jax.random.key(2), (3, 4))

    @jax.jit
    def run(params):
        unchanged = losses.lstm_loss(params, model, lat, lat[jnp.arange(3), t], t, 50.0, 0.5)[1]
        loss, m = losses.lstm_loss(params, model, lat, occ, t, 50.0, 0.5)
        z = lstm_encode(params, lat, model=model)
        z_occ = lstm_encode(params, losses.insert_occlusion(lat, occ, t), model=model)
        return unchanged, loss, m, z, z_occ

    unchanged, loss, m, z, z_occ = run(params)
    assert float(unchanged["matching"]) == 0.0  # occluded frame == clean frame: exactly zero
    np.testing.assert_allclose(z_occ[0, :1], z[0, :1])  # frames before t are untouched
    expected = np.mean([np.mean(np.sum((z[b, t[b]:] - z_occ[b, t[b]:]) ** 2, -1))
                        for b in range(3)])  # 1/(T-t+1) sum_{i>=t} ||z_i - z_i*||^2
    ae = np.mean(np.sum((z - lat) ** 2, -1))
    assert float(m["matching"]) > 0.0
    np.testing.assert_allclose(m["matching"], expected, rtol=1e-5)
    np.testing.assert_allclose(m["ae"], ae, rtol=1e-5)
    np.testing.assert_allclose(loss, 0.5 * ae + 50.0 * expected, rtol=1e-5)


def test_matching_distance_one_sided_stops_clean_gradient():
    clean, occ = jnp.array([[1.0, 2.0]]), jnp.array([[0.0, 4.0]])
    for one_sided in (False, True):
        d = losses.matching_distance(clean, occ, one_sided)
        np.testing.assert_allclose(d, [5.0])  # the same value either way: ||.||^2
        g_clean, g_occ = jax.grad(lambda c, o, s=one_sided: losses.matching_distance(c, o, s).sum(),
                                  argnums=(0, 1))(clean, occ)
        np.testing.assert_allclose(g_occ, [[-2.0, 4.0]])
        np.testing.assert_allclose(g_clean, [[0.0, 0.0]] if one_sided else [[2.0, -4.0]])


def test_lstm_training_with_occlusions(vae):
    vae_cfg, vae_state = vae
    cfg = LSTMConfig(hidden=32, batch_size=4, batches_per_epoch=30)
    frames = disc_images(8)
    images = jnp.stack([jnp.roll(frames, -i, axis=0) for i in range(4)])  # [B=4, T=8]
    latents = encoders.encode_mean(vae_state.params, vae_cfg, images)  # [4, 8, 6]
    state = encoders.init_lstm(jax.random.key(0), cfg, latents.shape[-1])

    occlusion = jax.jit(encoders.make_occlusion, static_argnames=("vae_cfg", "cfg"))(
        jax.random.key(1), vae_state.params, vae_cfg, images, cfg)
    assert occlusion.t.shape == (4,) and occlusion.latent.shape == (4, 6)
    assert bool(jnp.all((occlusion.t >= cfg.min_occlusion_t) & (occlusion.t < 8)))

    # Pre-training (auto-encoder loss only), then online steps with the matching loss.
    state, pre = jax.jit(encoders.lstm_fit_epoch, static_argnames="cfg")(
        state, jax.random.key(2), latents, cfg)
    assert float(pre["ae"][-5:].mean()) < float(pre["ae"][:5].mean())
    assert "matching" not in pre
    step = jax.jit(encoders.lstm_train_step, static_argnames="cfg")
    first = None
    for i in range(10):
        state, m = step(state, jax.random.key(3 + i), latents, cfg, occlusion)
        first = float(m["loss"]) if first is None else first
    assert np.isfinite(float(m["matching"])) and float(m["loss"]) < first
    assert int(state.step) == cfg.batches_per_epoch + 10
    with pytest.raises(ValueError, match="min_occlusion_t"):
        encoders.make_occlusion(jax.random.key(1), vae_state.params, vae_cfg, images[:, :1], cfg)
