"""Encoder losses (roll_jax.encoders.losses) and the training steps built on them (roll_jax.encoders.steps)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from configs.encoders import OCCLUSION_SHAPES, LSTMConfig, object_vae_config
from roll_jax.analysis import stats
from roll_jax.encoders import losses, models, steps
from roll_jax.encoders.models import LSTMEncoder, init_lstm_params, lstm_encode


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
FIT = jax.jit(steps.vae_fit_epoch, static_argnames="cfg")


@pytest.fixture(scope="module")
def vae():
    # The paper's beta 20 under the reference scaling (20 / 128 per image), on batches of 8,
    # with the cpu preset's VAE matching coefficient (the paper's 400 first shrinks the
    # latents; the scaling and the coefficient: docs/encoders.md, "Losses" and "The cpu preset's
    # encoder settings").
    cfg = object_vae_config("puck_push", batch_size=8, batches_per_epoch=25, matching_coef=4.0)
    return cfg, steps.init_vae(jax.random.key(0), cfg)


def test_effective_beta_is_beta_over_reference_batch():
    obj = object_vae_config("puck_push")
    assert obj.kl_per_batch_sum and obj.effective_beta == 20.0 / 128
    assert object_vae_config("puck_push", batch_size=32).effective_beta == 20.0 / 128
    assert object_vae_config("puck_push", kl_per_batch_sum=False).effective_beta == 20.0
    assert object_vae_config("puck_push", kl_reference_batch=None,
                             batch_size=32).effective_beta == 20.0 / 32
    with pytest.raises(ValueError, match="kl_reference_batch"):
        object_vae_config("puck_push", kl_reference_batch=0)
    with pytest.raises(ValueError, match="image_size must be 48 .* got 64"):
        object_vae_config("puck_push", image_size=64)


def test_vae_train_step_loss_is_the_reference_objective():
    """The step's loss equals (sum over the batch of SSE + beta * batch-mean KL + c * sum over
    batch and latent dims of the matching distance) / B, computed by hand."""
    b = 4
    cfg = object_vae_config("puck_push", batch_size=b, kl_reference_batch=b)
    state = steps.init_vae(jax.random.key(3), cfg)
    images = disc_images(b, radius=8.0)
    key = jax.random.key(5)
    _, metrics = jax.jit(steps.vae_train_step, static_argnames="cfg")(state, key, images, cfg)

    model = models.vae_model(cfg)
    k_noise, k_occ = jax.random.split(key)  # as vae_train_step splits its key
    occluded = losses.occlude(k_occ, images, None, cfg.occlusion_drop)
    mean, logvar = model.apply(state.params, images, method=type(model).encode)
    z = mean + np.exp(0.5 * np.asarray(logvar)) * jax.random.normal(k_noise, mean.shape)
    recon = np.asarray(model.apply(state.params, z, method=type(model).decode), np.float64)
    x = np.asarray(images, np.float64) / 255.0
    mean, logvar = np.asarray(mean, np.float64), np.asarray(logvar, np.float64)
    sse_sum = np.sum((recon - x) ** 2)
    kl_mean = np.mean(0.5 * np.sum(np.exp(logvar) + mean**2 - 1.0 - logvar, -1))
    m_occ = np.asarray(model.apply(state.params, occluded, method=type(model).encode)[0])
    match_sum = np.sum((mean - m_occ) ** 2)
    hand = (sse_sum + cfg.beta * kl_mean + cfg.matching_coef * match_sum) / b
    np.testing.assert_allclose(float(metrics["loss"]), hand, rtol=2e-5)
    assert float(metrics["matching"]) > 0.0  # the matching term took part


def test_arm_pair_term_is_the_partner_codes_distance():
    """vae_loss with partner images adds pair_coef x the batch mean of the squared distance
    between the images' and the partners' encoder means, and nothing else."""
    b = 4
    cfg = object_vae_config("puck_push", batch_size=b)
    state = steps.init_vae(jax.random.key(3), cfg)
    model = models.vae_model(cfg)
    images, partners = disc_images(b, radius=8.0), disc_images(b, radius=5.0)
    noise = jax.random.normal(jax.random.key(1), (b, cfg.latent_dim))
    base, m0 = losses.vae_loss(state.params, model, images, noise, 0.5)
    with_pair, m1 = losses.vae_loss(state.params, model, images, noise, 0.5, partners=partners,
                                    pair_coef=7.0)
    mu = np.asarray(model.apply(state.params, images, method=type(model).encode)[0], np.float64)
    mu_p = np.asarray(model.apply(state.params, partners, method=type(model).encode)[0],
                      np.float64)
    pair = np.mean(np.sum((mu - mu_p) ** 2, -1))
    assert pair > 0 and "pair" not in m0
    np.testing.assert_allclose(float(m1["pair"]), pair, rtol=1e-5)
    np.testing.assert_allclose(float(with_pair), float(base) + 7.0 * pair, rtol=1e-5)
    with pytest.raises(ValueError, match="partners"):
        losses.vae_loss(state.params, model, images, noise, 0.5, partners=partners[..., 0])


def test_gradient_in_parts_equals_the_whole_batch_gradient():
    """`grad_parts` slices give the whole batch's loss, metrics and gradient (float32
    roundoff), with the matching loss on; a batch that does not split is refused."""
    cfg = object_vae_config("puck_push", batch_size=8, matching_coef=400.0)
    state = steps.init_vae(jax.random.key(3), cfg)
    images = disc_images(8, radius=8.0)
    k_noise, k_occ = jax.random.split(jax.random.key(5))
    batch = (images, jax.random.normal(k_noise, (8, cfg.latent_dim)),
             losses.occlude(k_occ, images, None, cfg.occlusion_drop))

    def loss_fn(p, b):
        return losses.vae_loss(p, models.vae_model(cfg), b[0], b[1], cfg.effective_beta,
                               occluded=b[2], matching_coef=cfg.matching_coef)

    whole = jax.jit(lambda p, b: steps.grad_in_parts(loss_fn, p, b, 1))(state.params, batch)
    parts = jax.jit(lambda p, b: steps.grad_in_parts(loss_fn, p, b, 4))(state.params, batch)
    assert whole[1].keys() == parts[1].keys() and float(whole[1]["matching"]) > 0
    for k in whole[1]:
        np.testing.assert_allclose(float(parts[1][k]), float(whole[1][k]), rtol=1e-5, err_msg=k)
    for a, b in zip(jax.tree.leaves(whole[0]), jax.tree.leaves(parts[0])):
        scale = float(jnp.max(jnp.abs(a)))
        np.testing.assert_allclose(np.asarray(b), np.asarray(a), rtol=0, atol=1e-4 * scale)
    with pytest.raises(ValueError, match="batch of 8 does not split into grad_parts=3"):
        steps.grad_in_parts(loss_fn, state.params, batch, 3)
    with pytest.raises(ValueError, match="grad_parts=3 must be None or a positive divisor of "
                                         "batch_size=8"):
        object_vae_config("puck_push", batch_size=8, grad_parts=3)
    # auto: two slices on a CPU where the batch splits, the whole batch otherwise
    assert jax.default_backend() == "cpu"
    assert steps.grad_parts(cfg, 8) == 2 and steps.grad_parts(cfg, 7) == 1
    assert steps.grad_parts(object_vae_config("puck_push", batch_size=8, grad_parts=4), 8) == 4


def _random_discs(n: int, seed: int, radius: float = 5.0):
    """Segmented images of a disc at uniform random positions, and the positions [n, 2]."""
    rng = np.random.default_rng(seed)
    pos = rng.uniform(10.0, 38.0, (n, 2))
    yy, xx = np.mgrid[:48, :48]
    inside = ((yy[None] - pos[:, 0, None, None]) ** 2
              + (xx[None] - pos[:, 1, None, None]) ** 2) <= radius**2
    img = np.zeros((n, 48, 48, 3), np.uint8)
    img[inside] = (200, 60, 40)
    return jnp.asarray(img), pos


def _fit_discs(cfg, epochs: int = 4):
    """An object-VAE trained `epochs` epochs on 512 random-disc images from `cfg`; its last
    epoch's metrics and its latent means of 256 held-out discs with their positions."""
    train, _ = _random_discs(512, 0)
    test, test_pos = _random_discs(256, 1)
    state = steps.init_vae(jax.random.key(0), cfg)
    fit = jax.jit(steps.vae_fit_epoch, static_argnames="cfg")
    for epoch in range(epochs):
        state, m = fit(state, jax.random.key(10 + epoch), train, cfg)
    mean = jax.jit(models.encode_mean, static_argnames="cfg")(state.params, cfg, test)
    return m, np.asarray(mean), test_pos


@pytest.mark.parametrize("per_batch_sum", [True, False])
def test_object_vae_collapses_only_with_beta_per_image(per_batch_sum):
    """The paper's beta 20 on a moving-disc object-VAE: under the reference scaling (20/128
    per image) the latents encode the disc's position; applied per image, the posterior
    collapses to the prior."""
    cfg = object_vae_config("puck_push", batch_size=32, batches_per_epoch=100,
                            kl_per_batch_sum=per_batch_sum)
    m, mean, test_pos = _fit_discs(cfg)
    kl = float(m["kl"][-20:].mean())
    r2 = stats.position_r2(mean, test_pos)
    spread = float(np.max(np.std(mean, 0)))  # against the prior's (and posterior's) std ~1
    print(f"per_batch_sum={per_batch_sum}: KL {kl:.3f} nats, r2 {r2:.3f}, spread {spread:.3f}")
    if per_batch_sum:
        assert kl > 1.0 and r2 > 0.8 and spread > 0.2, (kl, r2, spread)
    else:  # collapsed: the means barely move and carry almost no nats
        assert kl < 0.1 and spread < 0.05, (kl, r2, spread)


def test_broadcast_decoder_lays_the_positions_out_flat():
    """With the spatial broadcast decoder the latent means are an affine image of the disc's
    position (R^2 0.999 here; Table 3's decoder reaches 0.95-0.98 on these discs) and their
    distances rank the positions' distances."""
    cfg = object_vae_config("puck_push", batch_size=32, batches_per_epoch=100, beta=5.0,
                            matching_coef=0.0, decoder="broadcast")
    _, mean, test_pos = _fit_discs(cfg)
    r2 = stats.position_r2(mean, test_pos)
    rank = stats.pairwise_spearman(mean, test_pos, max_n=len(mean))
    assert r2 > 0.99 and rank > 0.97, (r2, rank)


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


def test_occlude_edge_hides_one_side_of_the_object():
    img = disc_images(4, radius=10.0)
    obj = np.asarray(jnp.any(img != 0, -1))
    occ = losses.occlude_edge(jax.random.key(0), img, drop_frac=0.5)
    assert occ.dtype == jnp.uint8 and occ.shape == img.shape
    kept = np.asarray(jnp.any(occ != 0, -1))
    assert not np.any(kept & ~obj)
    assert bool(jnp.all(jnp.where(kept[..., None], occ == img, True)))
    for i in range(4):
        dropped = obj[i] & ~kept[i]
        assert dropped.sum() == int(0.5 * obj[i].sum())  # floor(drop_frac * n), exactly
        # A straight edge: the hidden and the visible halves of a disc of radius 10 lie
        # 2 * 4r / (3 pi) ~ 8.5 px apart; independent pixel drops leave them together.
        gap = np.linalg.norm(np.argwhere(dropped).mean(0) - np.argwhere(kept[i]).mean(0))
        assert gap > 6.0, gap
    np.testing.assert_array_equal(losses.occlude_edge(jax.random.key(0), img, drop_frac=0.0), img)
    empty = jnp.zeros((2, 48, 48, 3), jnp.uint8)
    assert not bool(jnp.any(losses.occlude_edge(jax.random.key(0), empty, drop_frac=0.5)))
    with pytest.raises(ValueError, match="occlusion_shape"):
        object_vae_config("puck_push", occlusion_shape="blob")
    assert tuple(losses.OCCLUSIONS) == OCCLUSION_SHAPES

def test_empty_images_give_finite_losses(vae):
    cfg, state = vae
    empty = jnp.zeros((8, 48, 48, 3), jnp.uint8)
    occ = losses.occlude(jax.random.key(0), empty, drop_frac=0.5)
    assert not bool(jnp.any(occ))
    # A whole epoch of object-VAE steps (with matching loss) on empty segmented images.
    new, metrics = FIT(state, jax.random.key(1), empty, cfg)
    assert all(np.isfinite(np.asarray(v)).all() for v in metrics.values())
    assert float(jnp.max(metrics["matching"])) == 0.0  # occluding nothing changes nothing
    assert all(np.isfinite(np.asarray(p)).all() for p in jax.tree.leaves(new.params))


def test_vae_matching_loss_zero_iff_unoccluded(vae):
    cfg, state = vae
    model = models.vae_model(cfg)
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
        mean = models.encode_mean(params, cfg, data)
        return jnp.mean(jnp.square(models.decode(params, cfg, mean) - data / 255.0))

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
    latents = models.encode_mean(vae_state.params, vae_cfg, images)  # [4, 8, 6]
    state = steps.init_lstm(jax.random.key(0), cfg, latents.shape[-1])

    occlusion = jax.jit(steps.make_occlusion, static_argnames=("vae_cfg", "cfg"))(
        jax.random.key(1), vae_state.params, vae_cfg, images, cfg)
    # The untrained VAE's means are ~1e-3 (its heads start at U(-1e-3, 1e-3)): unit scale, so
    # that the LSTM's losses are well above float32 noise.
    scale = 1.0 / float(jnp.std(latents))
    latents = latents * scale
    occlusion = occlusion.replace(latent=occlusion.latent * scale)
    assert occlusion.t.shape == (4,) and occlusion.latent.shape == (4, 6)
    assert bool(jnp.all((occlusion.t >= cfg.min_occlusion_t) & (occlusion.t < 8)))

    # Pre-training (auto-encoder loss only), then online steps with the matching loss.
    state, pre = jax.jit(steps.lstm_fit_epoch, static_argnames="cfg")(
        state, jax.random.key(2), latents, cfg)
    assert float(pre["ae"][-5:].mean()) < float(pre["ae"][:5].mean())
    assert "matching" not in pre
    step = jax.jit(steps.lstm_train_step, static_argnames="cfg")
    first = None
    for i in range(10):
        state, m = step(state, jax.random.key(3 + i), latents, cfg, occlusion)
        first = float(m["loss"]) if first is None else first
    assert np.isfinite(float(m["matching"])) and float(m["loss"]) < first
    assert int(state.step) == cfg.batches_per_epoch + 10
    with pytest.raises(ValueError, match="min_occlusion_t"):
        steps.make_occlusion(jax.random.key(1), vae_state.params, vae_cfg, images[:, :1], cfg)
