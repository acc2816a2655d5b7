"""Skew-Fit goals from the skewed replay distribution (vs a NumPy reference), and what each
ROLL ablation flag changes in the encoders and their online losses. Tiny shapes; the training
chunk is not compiled here (tests/test_train.py does that)."""

import dataclasses
import functools
import os

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats

from configs.encoders import VAEConfig
from configs.train import build_config, make_config
from roll_jax.agents import her, replay, skewfit
from roll_jax.encoders import losses, models, steps
from roll_jax.encoders.goal_encoding import PRIOR_BANK, Frozen, GoalEncoder, goal_encoder
from roll_jax.training import online
from roll_jax.training.state import TrainState, plan_chunk, skew_cdf_of, store_episodes
from roll_jax.common.checkpoint import write_meta

CAP, T, HW, A, DG = 5, 3, 4, 2, 2
T1 = T + 1
TINY_VAE = VAEConfig(latent_dim=DG, beta=1.0, feature_dim=4)
SKEWFIT = GoalEncoder(TINY_VAE, None, segment=False, lstm=False, skewed_goals=True)
PRIOR = GoalEncoder(TINY_VAE, None, segment=False, lstm=False)


def _buffer(size):
    """A buffer whose goal latent of frame (n, t) is (n * T1 + t, 0): draws are identifiable."""
    buf = replay.init_buffer(CAP, T, (HW, HW, 3), A, DG, DG)
    ids = np.arange(CAP * T1, dtype=np.float32).reshape(CAP, T1)
    goals = np.stack([ids, np.zeros_like(ids)], -1)
    return buf.replace(goal_latents=jnp.asarray(goals), size=jnp.int32(size))


def _np_weights(log_p, alpha, size):
    valid = np.broadcast_to((np.arange(log_p.shape[0]) < size)[:, None], log_p.shape)
    if not valid.any():
        return np.zeros(log_p.shape)
    logw = np.where(valid, alpha * log_p.astype(np.float64), -np.inf)
    w = np.exp(logw - logw[valid].max())
    return w / w.sum()


@pytest.mark.parametrize("alpha, size", [(-1.0, 3), (-0.5, CAP), (-1.0, 0)])
def test_skew_weights_match_numpy(alpha, size):
    log_p = np.random.default_rng(0).normal(-50.0, 3.0, (CAP, T1)).astype(np.float32)
    valid = skewfit.filled_frames(jnp.asarray(log_p), size)
    w = np.asarray(skewfit.skew_weights(jnp.asarray(log_p), alpha, valid))
    np.testing.assert_allclose(w, _np_weights(log_p, alpha, size), rtol=1e-5, atol=1e-12)
    assert np.all(w[size:] == 0)  # empty slots are never drawn
    cdf = np.asarray(skewfit.skew_cdf(jnp.asarray(log_p), alpha, size))
    np.testing.assert_allclose(cdf, np.cumsum(w), rtol=1e-5, atol=1e-7)


def test_skewing_starts_after_skew_start_epoch():
    """rlkit's start_skew_epoch: uniform over the filled frames up to that epoch (the goals and
    the online scene-VAE batches both draw from this CDF), p(x)^alpha after it."""
    cfg = make_config("puck_push", "skewfit", "smoke", skew_start_epoch=3)
    assert make_config("puck_push", "skewfit", "paper").skew_start_epoch == 10
    log_p = jnp.asarray(np.random.default_rng(2).normal(-50.0, 3.0, (CAP, T1)), jnp.float32)
    at = jax.jit(lambda e: skewfit.skew_cdf_at(cfg, log_p, 3, e))
    uniform = np.cumsum(_np_weights(np.zeros((CAP, T1)), -1.0, 3))
    for epoch in (0, 3):
        np.testing.assert_allclose(at(jnp.int32(epoch)), uniform, rtol=1e-6)
    np.testing.assert_allclose(at(jnp.int32(4)), skewfit.skew_cdf(log_p, cfg.skew_alpha, 3),
                               rtol=1e-6)
    assert np.abs(np.asarray(at(jnp.int32(4))) - uniform).max() > 0.1  # the skew is visible
    state = TrainState(sac=None, scene_vae=None, lstm=None, buffer=_buffer(3),
                       skew_log_p=log_p, env_state=None, test_start=None, last_train={},
                       key=None, env_steps=None, epoch=jnp.int32(2), eval_key=None)
    np.testing.assert_allclose(skew_cdf_of(cfg, SKEWFIT, state), uniform, rtol=1e-6)
    with pytest.raises(ValueError, match="skew_start_epoch must be >= 0, got -1"):
        make_config("puck_push", "skewfit", "smoke", skew_start_epoch=-1)


@functools.partial(jax.jit, static_argnums=(0, 4))
def _fresh(enc, buf, cdf, key, n):
    return her.fresh_goals(enc, buf, her.FreshGoals(cdf=cdf), key, n)


def test_skewed_goal_frequencies_match_weights():
    size, alpha, n = 3, -1.0, 40_000
    log_p = np.random.default_rng(1).normal(0.0, 1.0, (CAP, T1)).astype(np.float32)
    buf = _buffer(size)
    cdf = skewfit.skew_cdf(jnp.asarray(log_p), alpha, size)
    goals = np.asarray(_fresh(SKEWFIT, buf, cdf, jax.random.PRNGKey(0), n))
    assert np.all(goals[:, 1] == 0)
    counts = np.bincount(goals[:, 0].astype(int), minlength=CAP * T1)
    expected = _np_weights(log_p, alpha, size).reshape(-1) * n
    assert counts[expected == 0].sum() == 0  # unfilled slots
    hit = expected > 0
    chi2 = np.sum((counts[hit] - expected[hit]) ** 2 / expected[hit])
    assert stats.chi2.sf(chi2, hit.sum() - 1) > 1e-3, (counts, expected)


def test_fresh_goals_fall_back_to_prior_per_seed():
    """Under the seed vmap, an empty buffer (first episodes) gives N(0, I) goals and a filled
    one gives buffer frames; ROLL's goals come from its prior bank whatever the buffer holds."""
    log_p = jnp.zeros((CAP, T1))
    bufs = jax.tree.map(lambda a, b: jnp.stack([a, b]), _buffer(0), _buffer(2))
    cdfs = jax.vmap(lambda b: skewfit.skew_cdf(log_p, -1.0, b.size))(bufs)
    goals = np.asarray(jax.vmap(lambda b, c: her.fresh_goals(SKEWFIT, b, her.FreshGoals(cdf=c),
                                                             jax.random.PRNGKey(3), 4000))(bufs, cdfs))
    empty, filled = goals
    assert abs(empty.mean()) < 0.05 and abs(empty.std() - 1) < 0.05
    assert set(np.unique(filled[:, 0]).astype(int)) == set(range(2 * T1))  # uniform when log_p equal
    key = jax.random.PRNGKey(4)
    bank = her.FreshGoals(bank=her.goal_prior(make_config("puck_push", "roll", "smoke"), PRIOR,
                                              None, _buffer(3), key))
    np.testing.assert_array_equal(her.fresh_goals(PRIOR, _buffer(3), bank, key, 8),
                                  her.fresh_goals(PRIOR, _buffer(0), bank, key, 8))


def test_buffer_prior_matches_the_stored_frame_latents():
    """prior_goals "buffer": N(mean, std) of the filled slots' frame latents (rlkit's
    dist_mu / dist_std); N(0, 1) while the buffer is empty."""
    rng = np.random.default_rng(0)
    lat = rng.normal([2.0, -1.0], [0.5, 3.0], (CAP, T1, DG)).astype(np.float32)
    lat[3:] = 100.0  # unfilled slots: ignored
    buf = replay.init_buffer(CAP, T, (HW, HW, 3), A, DG, DG).replace(
        frame_latents=jnp.asarray(lat), size=jnp.int32(3))
    mean, std = jax.jit(her.frame_stats)(buf)
    np.testing.assert_allclose(mean, lat[:3].reshape(-1, DG).mean(0), rtol=1e-5)
    np.testing.assert_allclose(std, lat[:3].reshape(-1, DG).std(0), rtol=1e-5)
    empty = jax.jit(her.frame_stats)(buf.replace(size=jnp.int32(0)))
    np.testing.assert_array_equal(empty[0], 0.0)
    np.testing.assert_array_equal(empty[1], 1.0)
    goals = np.asarray(PRIOR.prior_goals(jax.random.PRNGKey(0), None, 20000, (mean, std)))
    np.testing.assert_allclose(goals.mean(0), mean, atol=0.05)
    np.testing.assert_allclose(goals.std(0), std, rtol=0.03)
    # The chunk's bank of prior goals (no LSTM here: the goals are the prior samples).
    key = jax.random.PRNGKey(1)
    bank = np.asarray(her.goal_prior(make_config("puck_push", "roll", "smoke",
                                                 prior_goals="buffer"), PRIOR, None, buf, key))
    assert bank.shape == (PRIOR_BANK, DG)
    np.testing.assert_allclose(bank.mean(0), mean, atol=0.15)
    np.testing.assert_allclose(bank.std(0), std, rtol=0.05)
    standard = np.asarray(her.goal_prior(make_config("puck_push", "roll", "smoke"), PRIOR, None,
                                         buf, key))
    np.testing.assert_allclose(standard.mean(0), 0.0, atol=0.05)
    np.testing.assert_allclose(standard.std(0), 1.0, rtol=0.05)
    assert her.goal_prior(make_config("puck_push", "skewfit", "smoke"), SKEWFIT, None, buf,
                          key) is None
    # Fresh goals for ROLL are rows of the bank.
    fresh = np.asarray(her.fresh_goals(PRIOR, buf, her.FreshGoals(bank=jnp.asarray(bank)), key,
                                       64))
    assert all((bank == row).all(1).any() for row in fresh)
    with pytest.raises(ValueError, match="unknown prior_goals 'data'"):
        make_config("puck_push", "roll", "smoke", prior_goals="data")


def test_store_episodes_writes_log_p_to_the_ring_slots():
    state = TrainState(sac=None, scene_vae=None, lstm=None,
                       buffer=replay.init_buffer(CAP, T, (HW, HW, 3), A, DG, DG),
                       skew_log_p=jnp.zeros((CAP, T1)), env_state=None, test_start=None,
                       last_train={}, key=None, env_steps=None, epoch=None, eval_key=None)
    store = jax.jit(store_episodes)
    for first in (0, 2, 4):  # slots 0,1 / 2,3 / 4,0
        ids = jnp.arange(first, first + 2, dtype=jnp.float32)
        traj = replay.Trajectory(
            images=jnp.zeros((2, T1, HW, HW, 3), jnp.uint8),
            object_images=jnp.zeros((2, T1, HW, HW, 3), jnp.uint8),
            actions=jnp.broadcast_to(ids[:, None, None], (2, T, A)),
            obs_latents=jnp.zeros((2, T1, DG)), frame_latents=jnp.zeros((2, T1, DG)),
            goal_latents=jnp.zeros((2, T1, DG)),
            rollout_goals=jnp.zeros((2, DG)))
        state = store(state, traj, jnp.broadcast_to(-ids[:, None], (2, T1)))
    np.testing.assert_array_equal(state.buffer.actions[:, 0, 0], [5, 1, 2, 3, 4])
    np.testing.assert_array_equal(state.skew_log_p, -np.broadcast_to(
        np.asarray(state.buffer.actions[:, :1, 0]), (CAP, T1)))


# ----------------------------------------------------------------------------- ablations

FLAGS = {"roll": {}, "no_matching_loss": {"matching_loss": False},
         "no_lstm": {"use_lstm": False}, "no_object_vae": {"use_object_vae": False}}
B, TT = 2, 4  # trajectories, frames per trajectory


@pytest.fixture(scope="module")
def data():
    cfg = make_config("puck_push", "roll", "smoke")
    k_o, k_s, k_img = jax.random.split(jax.random.PRNGKey(0), 3)
    rgb = jax.random.randint(k_img, (B, TT, 48, 48, 3), 1, 256).astype(jnp.uint8)
    blob = np.zeros((48, 48), bool)
    blob[10:20, 12:24] = True  # the "object" of the segmented images
    seg = jnp.where(jnp.asarray(blob)[..., None], rgb, 0).astype(jnp.uint8)
    return {"object": steps.init_vae(k_o, cfg.object_vae).params,
            "scene": steps.init_vae(k_s, cfg.scene).params, "rgb": rgb, "seg": seg}


def _norms(tree):
    return {k: float(sum(jnp.sum(jnp.square(x)) for x in jax.tree.leaves(v)))
            for k, v in tree["params"].items()}


def _lstm_loss(cfg, enc, lstm_params, vae_params, images):
    """The online LSTM loss as train_lstm builds it (cached frame latents, online_occlusion +
    lstm_train_step's loss), differentiable in the LSTM and in the frame encoder's parameters."""
    frozen = Frozen(seg=None, object_vae=vae_params if enc.object_cfg is not None else None)
    lat = enc.frame_latents(frozen, vae_params, images)  # the buffer's cached latents
    occ = online.online_occlusion(cfg, enc, frozen, vae_params, jax.random.PRNGKey(5), images)
    return losses.lstm_loss(lstm_params, models.lstm_model(cfg.lstm), lat,
                            None if occ is None else occ.latent, None if occ is None else occ.t,
                            matching_coef=cfg.lstm.matching_coef, ae_coef=cfg.lstm.ae_coef,
                            one_sided=cfg.lstm.matching_one_sided)


@pytest.mark.parametrize("variant", list(FLAGS))
def test_ablation_changes_exactly_its_part(variant, data):
    cfg = make_config("puck_push", "roll", "smoke", **FLAGS[variant])
    enc = goal_encoder(cfg)
    obj_latent, scene_latent = cfg.object_vae.latent_dim, cfg.scene.latent_dim
    # Structure: which encoders exist and what the LSTM sees.
    assert not enc.skewed_goals  # ROLL keeps prior goals
    assert enc.segment == (variant != "no_object_vae")
    assert enc.lstm == (variant != "no_lstm")
    assert (enc.object_cfg is None) == (variant == "no_object_vae")
    assert enc.frame_dim == (scene_latent if variant == "no_object_vae" else obj_latent)
    # Object-VAE matching loss: on for ROLL only ("without matching loss" drops it on both
    # the LSTM and the object-VAE; "without LSTM and matching loss" too).
    if enc.object_cfg is not None:
        want = cfg.object_vae.matching_coef if variant == "roll" else 0.0
        assert cfg.object_vae.matching_coef > 0 and enc.object_cfg.matching_coef == want
        assert enc.object_cfg.latent_dim == obj_latent
    if not enc.lstm:
        assert all(plan_chunk(cfg, e).lstm_batches == 0 for e in range(4))
        x = jnp.ones((TT, enc.frame_dim))
        assert enc.sequence(None, x) is x and enc.goal_dim == obj_latent
        return
    assert any(plan_chunk(cfg, e).lstm_batches > 0 for e in range(4))
    lstm = steps.init_lstm(jax.random.PRNGKey(1), cfg.lstm, enc.frame_dim)
    for gate in ("ii", "if", "ig", "io"):  # input kernels of the first cell: [frame_dim, hidden]
        assert lstm.params["params"]["cells_0"][gate]["kernel"].shape[0] == enc.frame_dim
    vae_params = data["object"] if enc.object_cfg is not None else data["scene"]
    images = data["seg"] if enc.segment else data["rgb"]
    fn = jax.jit(jax.grad(functools.partial(_lstm_loss, cfg, enc), argnums=(0, 1), has_aux=True))
    (g_lstm, g_vae), m = fn(lstm.params, vae_params, images)
    # Every LSTM part learns; the frozen frame encoder gets nothing from the LSTM loss.
    assert all(v > 0 for v in _norms(g_lstm).values()), _norms(g_lstm)
    assert all(v == 0 for v in _norms(g_vae).values())
    if variant == "no_matching_loss":
        assert "matching" not in m and float(m["loss"]) == float(cfg.lstm.ae_coef * m["ae"])
    else:
        assert float(m["matching"]) > 0
        np.testing.assert_allclose(m["loss"], cfg.lstm.ae_coef * m["ae"]
                                   + cfg.lstm.matching_coef * m["matching"], rtol=1e-6)
        # The matching term alone moves the LSTM.
        match_only = jax.jit(jax.grad(lambda p: _lstm_loss(
            cfg, enc, p, vae_params, images)[1]["matching"]))(lstm.params)
        assert all(v > 0 for v in _norms(match_only).values())


@pytest.mark.parametrize("variant", ["roll", "no_matching_loss", "no_lstm"])
def test_object_vae_matching_gradient(variant, data):
    """The object-VAE pretraining loss (vae_train_step with the encoder's config): its matching
    term moves every encoder part for ROLL and is exactly zero under the ablations."""
    ocfg = goal_encoder(make_config("puck_push", "roll", "smoke", **FLAGS[variant])).object_cfg
    imgs = data["seg"][0]
    occ = losses.occlude(jax.random.PRNGKey(2), imgs, None, ocfg.occlusion_drop)
    grad = jax.jit(jax.grad(lambda p, c: c * losses.vae_matching_loss(
        p, models.vae_model(ocfg), imgs, occ, ocfg.matching_one_sided)))
    norms = _norms(grad(data["object"], ocfg.matching_coef))
    means = [k for k in norms if k.startswith("convs_") or k in ("feature", "mean_head")]
    if variant == "roll":  # the encoder-mean path only: the loss compares means
        assert len(means) > 2 and all(norms[k] > 0 for k in means), norms
        assert all(norms[k] == 0 for k in norms if k not in means)
    else:
        assert all(v == 0 for v in norms.values())
    _, m = jax.jit(steps.vae_train_step, static_argnames="cfg")(
        steps.ModelState(data["object"], steps.vae_optimizer(ocfg).init(data["object"]),
                          jnp.int32(0)), jax.random.PRNGKey(3), imgs, cfg=ocfg)
    assert ("matching" in m) == (variant == "roll")


def test_skewfit_has_no_lstm_object_vae_or_segmentation():
    cfg = make_config("puck_push", "skewfit", "smoke")
    enc = goal_encoder(cfg)
    assert enc.skewed_goals and not enc.lstm and not enc.segment and enc.object_cfg is None
    assert enc.goal_dim == cfg.scene.latent_dim == 4  # Table 2: Skew-Fit puck latent size
    assert all(plan_chunk(cfg, e).lstm_batches == 0 for e in range(4))
    rgb = jnp.zeros((2, 48, 48, 3), jnp.uint8)
    assert enc.goal_images(Frozen(seg=None, object_vae=None), rgb) is rgb


def test_no_object_vae_lstm_reconstructs_scene_latents_on_every_task():
    from configs.train import TASKS

    for task in TASKS:
        cfg = make_config(task, "roll", "smoke", use_object_vae=False)
        assert cfg.lstm.out_dim == cfg.scene.latent_dim, task
    with pytest.raises(ValueError, match="lstm.out_dim=6 must equal the scene-VAE latent size 16"):
        dataclasses.replace(make_config("door_open", "roll", "smoke", achieved_encoding="single"),
                            use_object_vae=False)


def test_encoder_checkpoint_of_full_roll_is_refused_by_the_matching_ablation(tmp_path):
    from roll_jax.encoders import pretrain

    full = make_config("hurdle_top", "roll", "smoke")
    ablated = make_config("hurdle_top", "roll", "smoke", matching_loss=False)
    os.makedirs(tmp_path / "enc")
    write_meta(str(tmp_path / "enc"), pretrain._meta(full))
    with pytest.raises(ValueError, match="object_matching_coef"):
        pretrain.load(str(tmp_path / "enc"), ablated)


def test_encoder_checkpoint_of_another_decoder_is_refused(tmp_path):
    from roll_jax.encoders import pretrain
    from configs.train import build_config

    table3 = build_config("puck_push", "roll", "smoke")
    broadcast = build_config("puck_push", "roll", "smoke",
                             overrides=["object_vae.decoder=broadcast"])
    os.makedirs(tmp_path / "enc")
    write_meta(str(tmp_path / "enc"), pretrain._meta(broadcast))
    with pytest.raises(ValueError, match="object_decoder='broadcast'.*needs object_decoder='deconv'"):
        pretrain.load(str(tmp_path / "enc"), table3)
    # A checkpoint whose meta predates the choice holds Table 3's decoders.
    older = {k: v for k, v in pretrain._meta(table3).items() if not k.endswith("_decoder")}
    write_meta(str(tmp_path / "enc"), older)
    with pytest.raises(ValueError, match="object_decoder='deconv'.*needs object_decoder='broadcast'"):
        pretrain.load(str(tmp_path / "enc"), broadcast)


def test_encoder_checkpoint_of_the_old_kl_scaling_is_refused(tmp_path):
    from roll_jax.encoders import pretrain

    cfg = make_config("puck_push", "roll", "smoke")
    old = {**pretrain._meta(cfg), "version": 1}
    write_meta(str(tmp_path / "enc"), old)
    with pytest.raises(ValueError, match="beta per image"):
        pretrain.load(str(tmp_path / "enc"), cfg)


def test_log_likelihood_is_the_reference_estimator():
    """skewfit.log_likelihood against rlkit's estimator written out in NumPy: the mean over K
    samples z = mu + sigma eps of log N(z; 0, I) - log N(z; mu, sigma) - SSE(clip(dec(z)), x)
    / (2e), constants dropped; images that decode worse get a lower log p."""
    cfg = make_config("puck_push", "skewfit", "smoke")
    params = steps.init_vae(jax.random.PRNGKey(0), cfg.scene).params
    rng = np.random.default_rng(0)
    images = jnp.asarray(rng.integers(0, 256, (3, 48, 48, 3)), jnp.uint8)
    images = images.at[0].set(0)  # a black image: nearest to the untrained decoder's output
    key = jax.random.PRNGKey(3)
    got = np.asarray(skewfit.log_likelihood(cfg, params, images, key))
    model = models.vae_model(cfg.scene)
    from roll_jax.encoders.models import ConvVAE

    mu, logvar = (np.asarray(a, np.float64) for a in model.apply(params, images,
                                                                 method=ConvVAE.encode))
    eps = np.asarray(jax.random.normal(key, (cfg.skew_num_latents,) + mu.shape), np.float64)
    z = mu + np.exp(0.5 * logvar) * eps
    dec = np.clip(np.asarray(model.apply(params, jnp.asarray(z, jnp.float32),
                                         method=ConvVAE.decode), np.float64), 0, 1)
    x = np.asarray(images, np.float64) / 255
    log_d = -0.5 * np.square(dec - x).sum((-3, -2, -1)) / np.e
    log_pz = -0.5 * np.square(z).sum(-1)
    log_qz = -0.5 * (np.square(eps) + logvar).sum(-1)
    np.testing.assert_allclose(got, (log_d + log_pz - log_qz).mean(0), rtol=1e-4)
    assert got[0] > got[1] and got[0] > got[2]


def test_online_scene_vae_round_recomputes_log_p_of_the_filled_episodes_only():
    """After a scene-VAE round, skew_log_p holds frame_log_p of every filled episode under the
    trained VAE (one key per episode, `replay.map_filled`) and keeps the unfilled slots."""
    cfg = make_config("puck_push", "skewfit", "smoke")
    vae = steps.init_vae(jax.random.PRNGKey(0), cfg.scene)
    cap, t = 4, 2
    buf = replay.init_buffer(cap, t, (48, 48, 3), A, cfg.scene.latent_dim, cfg.scene.latent_dim)
    rng = np.random.default_rng(1)
    buf = buf.replace(images=jnp.asarray(rng.integers(0, 256, buf.images.shape), jnp.uint8),
                      size=jnp.int32(3))
    state = TrainState(sac=None, scene_vae=vae, lstm=None, buffer=buf,
                       skew_log_p=jnp.full((cap, t + 1), -5.0), env_state=None,
                       test_start=None, last_train={}, key=None, env_steps=None,
                       epoch=jnp.int32(1), eval_key=None)
    key = jax.random.PRNGKey(2)
    new, _ = jax.jit(lambda s: online.train_scene_vae(cfg, s, key, 2))(state)
    keys = jax.random.split(jax.random.split(key)[0], cap)  # train_scene_vae's k_lp
    for i in range(3):
        np.testing.assert_allclose(
            new.skew_log_p[i], skewfit.frame_log_p(cfg, new.scene_vae.params, buf.images[i],
                                                   keys[i]), rtol=1e-4)
    np.testing.assert_array_equal(np.asarray(new.skew_log_p[3]), -5.0)


def test_single_achieved_encoding_is_the_goal_images_function_frame_by_frame():
    seq = goal_encoder(make_config("puck_push", "roll", "smoke", achieved_encoding="sequence"))
    one = goal_encoder(make_config("puck_push", "roll", "smoke", achieved_encoding="single"))
    assert seq.achieved_by.name == "sequence" and one.achieved_by.name == "single"
    assert goal_encoder(make_config("puck_push", "roll", "smoke")).achieved_by.name == "held"
    cfg = make_config("puck_push", "roll", "smoke")
    lstm = steps.init_lstm(jax.random.PRNGKey(1), cfg.lstm, seq.frame_dim)
    x = jax.random.normal(jax.random.PRNGKey(2), (TT, seq.frame_dim))
    single = one.achieved(lstm.params, x, None)
    # frame t alone, one step from the zero state: what a goal image of that frame gets
    for t in (0, 3, TT - 1):
        np.testing.assert_allclose(single[t], one.single(lstm.params, x[t]), rtol=1e-5, atol=1e-6)
    sequence = seq.achieved(lstm.params, x, None)
    np.testing.assert_allclose(sequence[0], single[0], rtol=1e-5, atol=1e-6)  # same first step
    assert float(jnp.abs(sequence[1:] - single[1:]).max()) > 1e-4  # later steps remember


def test_held_achieved_encoding_keeps_the_last_goal_that_showed_the_object():
    cfg = make_config("puck_push", "roll", "smoke", achieved_encoding="held", held_min_pixels=5)
    held = goal_encoder(cfg)
    one = goal_encoder(make_config("puck_push", "roll", "smoke", achieved_encoding="single"))
    lstm = steps.init_lstm(jax.random.PRNGKey(1), cfg.lstm, held.frame_dim)
    x = jax.random.normal(jax.random.PRNGKey(2), (9, held.frame_dim))
    images = np.zeros((9, 48, 48, 3), np.uint8)
    images[:, 10:13, 10:13, 1] = 40  # 9 object pixels: shown
    images[3:7] = 0  # frames 3-5: hidden
    images[6, 10, 10:14, 0] = 7  # frame 6: 4 pixels, fewer than 5: hidden too
    got = held.achieved(lstm.params, x, jnp.asarray(images))
    single = one.achieved(lstm.params, x, None)
    for t in range(9):
        want = single[2] if 3 <= t <= 6 else single[t]
        np.testing.assert_allclose(got[t], want, rtol=1e-5, atol=1e-6)
    # An episode that starts hidden keeps its first frame's own goal until the object shows.
    images[:2] = 0
    got = held.achieved(lstm.params, x, jnp.asarray(images))
    np.testing.assert_allclose(got[1], single[0], rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(got[2], single[2], rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("overrides, pattern", [
    (dict(achieved_encoding="held", use_object_vae=False), "no-object-vae"),
    (dict(achieved_encoding="held", held_min_pixels=0), "held_min_pixels must be positive, got 0"),
])
def test_held_encoding_refuses_what_it_cannot_count(overrides, pattern):
    with pytest.raises(ValueError, match=pattern):
        make_config("puck_push", "roll", "smoke", **overrides)


def test_no_object_vae_takes_single_achieved_goals_unless_held_is_asked_for():
    # Nothing is segmented without the object-VAE, so the default "held" becomes "single";
    # asking for "held" explicitly is refused rather than changed.
    assert make_config("puck_push", "roll", "smoke").achieved_encoding == "held"
    cfg = build_config("puck_push", "roll", "smoke", use_object_vae=False)
    assert cfg.achieved_encoding == "single"
    assert goal_encoder(cfg).achieved_by.name == "single"
    with pytest.raises(ValueError, match="no-object-vae"):
        build_config("puck_push", "roll", "smoke", overrides=['achieved_encoding="held"'],
                     use_object_vae=False)
