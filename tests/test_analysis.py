"""roll_jax.analysis: Spearman, latent-vs-distance (Figure 5), occlusion retrieval (App. A).

Synthetic images and ideal encoders; no environment, no pretrained checkpoint."""
import dataclasses
import json
import os

import jax
import numpy as np
import pytest

from roll_jax.analysis import fig5, occlusion, stats

# ----------------------------------------------------------------------------- statistics

def test_rankdata_average_ties():
    np.testing.assert_array_equal(stats.rankdata([3.0, 1.0, 2.0, 2.0]), [4.0, 1.0, 2.5, 2.5])
    np.testing.assert_array_equal(stats.rankdata([5, 5, 5]), [2.0, 2.0, 2.0])
    np.testing.assert_array_equal(stats.rankdata([0.1, 0.3, 0.3, 0.3, -1.0]),
                                  [2.0, 4.0, 4.0, 4.0, 1.0])


def test_spearman_hand_computed_with_ties():
    # x ranks [1, 2.5, 2.5, 4], y ranks [1, 3, 2, 4]; centred: [-1.5, 0, 0, 1.5] and
    # [-1.5, .5, -.5, 1.5]; cov 4.5, var 4.5 and 5 -> rho = 4.5 / sqrt(22.5) = sqrt(0.9).
    rho = stats.spearman([1.0, 2.0, 2.0, 3.0], [10.0, 30.0, 20.0, 40.0])
    assert rho == pytest.approx(np.sqrt(0.9), abs=1e-12)
    assert stats.spearman([1, 2, 3, 4], [8, 4, 2, 1]) == pytest.approx(-1.0)
    assert stats.spearman([1, 2, 3], [1, 10, 1000]) == pytest.approx(1.0)  # monotone only
    assert np.isnan(stats.spearman([1, 2, 3], [7, 7, 7]))  # constant: undefined
    with pytest.raises(ValueError, match="same length"):
        stats.spearman([1, 2, 3], [1, 2])


def test_spearman_matches_scipy_when_available():
    scipy_stats = pytest.importorskip("scipy.stats")
    rng = np.random.default_rng(0)
    x = rng.integers(0, 6, 40).astype(float)  # many ties
    y = x + rng.integers(0, 4, 40)
    assert stats.spearman(x, y) == pytest.approx(scipy_stats.spearmanr(x, y).statistic,
                                                  abs=1e-12)


# ----------------------------------------------------------------------------- Figure 5

def _index_images(n):
    """uint8 [n, 48, 48, 3] whose pixel (0, 0, 0..1) holds the image's index (16 bit)."""
    img = np.zeros((n, 48, 48, 3), np.uint8)
    idx = np.arange(n)
    img[:, 0, 0, 0], img[:, 0, 0, 1] = idx % 256, idx // 256
    return img


def _read_index(images):
    images = np.asarray(images)
    return images[:, 0, 0, 0].astype(int) + 256 * images[:, 0, 0, 1].astype(int)


def test_position_probe_tells_an_encoding_from_noise():
    rng = np.random.default_rng(0)
    pos = rng.uniform(-0.1, 0.1, (400, 2))
    mix = rng.normal(size=(2, 6))
    good = pos @ mix + 0.001 * rng.normal(size=(400, 6))  # a linear code of the position
    noise = rng.normal(size=(400, 6))
    assert stats.position_r2(good, pos) > 0.99
    assert stats.position_r2(noise, pos) < 0.1
    assert stats.pairwise_spearman(good, pos) > 0.9  # (the code is anisotropic)
    assert abs(stats.pairwise_spearman(noise, pos)) < 0.1
    # A monotone but non-linear code still ranks (Spearman) but fits worse (R^2).
    warped = np.concatenate([np.tanh(pos * 30), pos[:, :1] * 0], 1)
    assert stats.pairwise_spearman(warped, pos) > 0.8


def test_nonlinear_probes_tell_a_curved_code_from_a_missing_one():
    rng = np.random.default_rng(0)
    pos = rng.uniform(-0.1, 0.1, (400, 2))
    # Each coordinate on an arc of +-2.5 rad: the whole position, but not affinely.
    curved = np.concatenate([np.cos(25 * pos), np.sin(25 * pos)], 1)
    r2 = stats.position_r2_nonlinear(curved, pos)
    assert stats.position_r2(curved, pos) < 0.9 and r2["affine_cv"] < 0.9
    assert r2["quadratic_cv"] > r2["affine_cv"] + 0.05 and r2["knn"] > 0.97
    noise = stats.position_r2_nonlinear(rng.normal(size=(400, 6)), pos)
    assert max(noise.values()) < 0.1
    with pytest.raises(ValueError, match="got 8 latents and 8 states"):
        stats.position_r2_nonlinear(curved[:8], pos[:8])


def _disc_labels(centres, radius=3.0, size=48):
    rows, cols = np.mgrid[0:size, 0:size]
    c = np.asarray(centres, np.float64)
    disc = (rows - c[:, 0, None, None]) ** 2 + (cols - c[:, 1, None, None]) ** 2 <= radius ** 2
    return np.where(disc, 2, 0).astype(np.int32)


def test_pixel_reference_ranks_visible_discs_and_counts_hidden_ones():
    rng = np.random.default_rng(0)
    n = 200
    pos = rng.uniform(10.0, 38.0, (n, 2))  # the object state: here the disc centre itself
    goal = np.array([24.0, 24.0])
    labels = _disc_labels(pos)
    obs = fig5.ObservationSet(
        rgb=np.zeros((n, 48, 48, 3), np.uint8), goal_rgb=np.zeros((48, 48, 3), np.uint8),
        distances=np.linalg.norm(pos - goal, axis=-1), states=pos, labels=labels,
        goal_labels=_disc_labels(goal[None])[0], goal_state=goal)
    ref = fig5.pixel_reference(obs)
    assert ref["reference_spearman_object"] > 0.98
    near = fig5.near_goal(obs.distances)
    assert near.sum() == 40 and obs.distances[near].max() < obs.distances[~near].min()
    assert ref["reference_near_goal_spearman_object"] > 0.9
    assert ref["reference_r2"] > 0.99 and ref["reference_pairwise_spearman"] > 0.98
    assert ref["share_object_hidden"] == 0.0 and ref["share_object_partly_hidden"] == 0.0

    # An arm (robot label 1) painted over 20 discs entirely and over 30 by half of their rows
    covered = labels.copy()
    covered[:20] = np.where(covered[:20] == 2, 1, covered[:20])
    rows = np.arange(48)[None, :, None]
    half = (rows < pos[20:50, 0, None, None]) & (covered[20:50] == 2)
    covered[20:50] = np.where(half, 1, covered[20:50])
    hidden = fig5.pixel_reference(dataclasses.replace(obs, labels=covered))
    assert hidden["share_object_hidden"] == pytest.approx(0.1)
    assert hidden["share_object_partly_hidden"] == pytest.approx(0.15)
    assert hidden["reference_spearman_object"] < ref["reference_spearman_object"] - 0.05
    np.testing.assert_allclose(fig5.object_visibility(covered)[:20], 0.0)

    # The known-state reference: exact where nothing hides the object; with the 20 hidden
    # discs at the shown ones' mean it loses rank, but sees through the 30 half-hidden ones,
    # which pull the visible centroid off the centre.
    assert ref["known_spearman_object"] == pytest.approx(1.0)
    assert ref["known_r2"] == pytest.approx(1.0)
    assert ref["known_pairwise_spearman"] == pytest.approx(1.0)
    guess = pos[20:].mean(0)
    est = np.concatenate([np.repeat(guess[None], 20, 0), pos[20:]])
    assert hidden["known_r2"] == pytest.approx(stats.position_r2(est, pos))
    d = np.concatenate([np.full(20, np.linalg.norm(guess - goal)), obs.distances[20:]])
    assert hidden["known_spearman_object"] == pytest.approx(stats.spearman(obs.distances, d))
    assert hidden["known_spearman_object"] < 0.99
    assert hidden["known_pairwise_spearman"] > hidden["reference_pairwise_spearman"]
    with pytest.raises(ValueError, match="every one of the 200 observations hides"):
        fig5.pixel_reference(dataclasses.replace(obs, labels=np.where(labels == 2, 1, labels)))


def test_goal_mask_scores_compare_the_goal_mask_with_its_labels():
    from configs.segmentation import segmentation_config
    from roll_jax.segmentation import pipeline

    # An unfitted background model calls every pixel foreground; the threshold then decides
    # whether the U-Net calls all of them robot (-1) or none (2: probabilities are < 1).
    seg = pipeline.initial_params(48, 48, 3, segmentation_config("pickup", "smoke"))
    labels = np.zeros((48, 48), np.int32)
    labels[10:14, 10:14] = 2  # 16 object pixels
    labels[30:34, 5:10] = 1  # 20 robot pixels
    obs = fig5.ObservationSet(
        rgb=np.zeros((1, 48, 48, 3), np.uint8), goal_rgb=np.full((48, 48, 3), 90, np.uint8),
        distances=np.zeros(1), states=np.zeros((1, 2)), labels=labels[None], goal_labels=labels,
        goal_state=np.zeros(2))
    everything = fig5.goal_mask_scores(seg.replace(robot_threshold=np.float32(2.0)), obs)
    assert everything == {"goal_object_pixels": 16, "goal_mask_iou": round(16 / 48 ** 2, 4),
                          "goal_mask_robot_leakage": 1.0}
    nothing = fig5.goal_mask_scores(seg.replace(robot_threshold=np.float32(-1.0)), obs)
    assert nothing["goal_mask_iou"] == 0.0 and nothing["goal_mask_robot_leakage"] == 0.0


def test_latent_vs_distance_monotone_object_latent(tmp_path):
    rng = np.random.default_rng(1)
    n = 60
    dist = rng.uniform(0.0, 0.25, n)  # metres
    images = _index_images(n + 1)
    obs, goal = images[:n], images[n]  # index n is the goal
    # Object latent: the goal at the origin, observation i at g(d_i) along a random direction
    # with g monotone, so ||z_i - z_g|| = g(d_i). Scene latent: unrelated random vectors.
    dirs = rng.normal(size=(n + 1, 6))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    radius = np.r_[np.exp(3.0 * dist) - 0.5, 0.0]
    obj_table = dirs * radius[:, None]
    scene_table = rng.normal(size=(n + 1, 4))

    res = fig5.latent_vs_distance(obs, goal, dist,
                                      encode_scene=lambda x: scene_table[_read_index(x)],
                                      encode_object=lambda x: obj_table[_read_index(x)])
    assert res["n"] == n
    assert res["spearman_object"] == pytest.approx(1.0, abs=1e-12)
    assert abs(res["spearman_scene"]) < 0.5
    np.testing.assert_allclose(res["object_latent_distance"], radius[:n], rtol=1e-9, atol=1e-12)
    near = dist <= res["near_goal_distance"]
    assert near.sum() == pytest.approx(0.2 * n, abs=1)
    assert res["near_goal_spearman_object"] == pytest.approx(1.0, abs=1e-12)
    # An encoder that ranks the far observations but reverses the near ones: high overall,
    # reversed near the goal.
    r = radius[:n].copy()
    idx = np.flatnonzero(near)
    r[idx[np.argsort(dist[idx])]] = np.sort(r[idx])[::-1]
    far_only = np.r_[r, 0.0][:, None] * dirs
    res2 = fig5.latent_vs_distance(obs, goal, dist,
                                   encode_scene=lambda x: scene_table[_read_index(x)],
                                   encode_object=lambda x: far_only[_read_index(x)])
    assert res2["spearman_object"] > 0.8
    assert res2["near_goal_spearman_object"] == pytest.approx(-1.0, abs=1e-12)

    png, js = fig5.write_latent_vs_distance(res, str(tmp_path), "puck_push")
    assert os.path.getsize(png) > 1000
    with open(png, "rb") as f:
        assert f.read(8) == b"\x89PNG\r\n\x1a\n"
    with open(js) as f:
        out = json.load(f)
    assert {"spearman_object", "spearman_scene", "n", "task"} <= set(out)
    assert out["near_goal_spearman_object"] == pytest.approx(1.0)
    assert out["task"] == "puck_push" and out["n"] == n
    assert out["spearman_object"] == pytest.approx(1.0)
    assert len(out["object_distance"]) == n


# ----------------------------------------------------------------------------- occlusion

def _disc_trajectories(b, t_len, rng):
    """Segmented images with a disc (the object, mask = disc) and the position in cm written
    into row 0 (outside the mask, so occlusion never touches it); positions in metres."""
    pos_cm = rng.integers(0, 40, size=(b, t_len, 2))
    images = np.zeros((b, t_len, 48, 48, 3), np.uint8)
    yy, xx = np.mgrid[0:48, 0:48]
    masks = np.zeros((b, t_len, 48, 48), bool)
    for i in range(b):
        for t in range(t_len):
            cy, cx = 8 + pos_cm[i, t]
            masks[i, t] = (yy - cy) ** 2 + (xx - cx) ** 2 <= 16
    images[masks] = (200, 120, 40)
    images[:, :, 0, 0, 0] = pos_cm[..., 0]
    images[:, :, 0, 1, 0] = pos_cm[..., 1]
    return images, masks, pos_cm / 100.0


def test_occlude_frames_drops_85_percent_of_object_pixels():
    rng = np.random.default_rng(2)
    images, masks, _ = _disc_trajectories(16, 5, rng)
    t, occ = occlusion.occlude_frames(jax.random.PRNGKey(0), images, masks, drop=0.85)
    assert t.shape == (16,) and t.min() >= 1 and t.max() <= 4
    before = masks[np.arange(16), t].sum()
    after = (occ.any(-1) & masks[np.arange(16), t]).sum()
    assert after / before == pytest.approx(0.15, abs=0.04)
    # pixels outside the mask are untouched
    outside = ~masks[np.arange(16), t]
    np.testing.assert_array_equal(occ[outside], images[np.arange(16), t][outside])


def test_occlusion_retrieval_perfect_encoder_has_zero_error(tmp_path):
    rng = np.random.default_rng(3)
    images, masks, pos = _disc_trajectories(8, 6, rng)

    def read_position(x):  # the "perfect" frame encoder: the true position
        return np.asarray(x)[:, 0, :2, 0].astype(np.float64)

    heads = {name: (lambda z: z) for name in occlusion.OCCLUSION_MODELS}
    res = occlusion.occlusion_retrieval(jax.random.PRNGKey(1), images, masks, pos,
                                       read_position, heads)
    assert set(res["error_cm"]) == {"lstm_matching", "lstm", "vae"}
    for name in occlusion.OCCLUSION_MODELS:
        assert res["error_cm"][name] == [0.0, 0.0]
    assert res["n_queries"] == 8 and res["pool_size"] == 48 and res["chance_cm"] > 0

    png, js = occlusion.write_occlusion(res, str(tmp_path), "hurdle_top")
    assert os.path.getsize(png) > 1000
    with open(js) as f:
        out = json.load(f)
    assert out["error_cm"] == {"lstm_matching": [0.0, 0.0], "lstm": [0.0, 0.0],
                               "vae": [0.0, 0.0]}
    assert out["median_cm"] == {"lstm_matching": 0.0, "lstm": 0.0, "vae": 0.0}

    # A blind encoder (a constant) retrieves an arbitrary frame: positive error.
    res = occlusion.occlusion_retrieval(jax.random.PRNGKey(1), images, masks, pos,
                                       lambda x: np.zeros((len(x), 2)), {"vae": lambda z: z})
    assert res["error_cm"]["vae"][0] > 0
    assert res["median_cm"]["vae"] == np.median(res["errors_cm"]["vae"])


def test_retrieval_errors_uses_history_head():
    """A head that reads the previous frame's code (an ideal 'LSTM' that remembers) still
    finds the occluded frame when the frame itself is unreadable."""
    b, t_len = 5, 4
    pos = np.arange(b * t_len * 2, dtype=float).reshape(b, t_len, 2)
    # code_t = position at t-1 (code_0: a distinct marker): frame t itself is never read
    clean = np.concatenate([-1000.0 - pos[:, :1], pos[:, :-1]], 1)
    occ_t = np.array([1, 2, 3, 1, 2])
    err, nn = occlusion.retrieval_errors(clean, clean[np.arange(b), occ_t], pos, occ_t)
    np.testing.assert_array_equal(err, 0.0)
    np.testing.assert_array_equal(nn, np.arange(b) * t_len + occ_t)
    # From the other trajectories only, the query's own frame cannot be retrieved.
    err, nn = occlusion.retrieval_errors(clean, clean[np.arange(b), occ_t], pos, occ_t,
                                        exclude_own=True)
    assert np.all(nn // t_len != np.arange(b)) and np.all(err > 0)


def test_retrieval_from_other_trajectories_finds_the_same_position_elsewhere():
    pos = np.array([[[0.0, 0.0], [1.0, 0.0]], [[5.0, 5.0], [1.0, 0.01]], [[9.0, 9.0], [8.0, 8.0]]])
    occ_t = np.array([1, 1, 1])
    err, nn = occlusion.retrieval_errors(pos, pos[np.arange(3), occ_t], pos, occ_t,
                                        exclude_own=True)
    assert nn[0] == 3 and nn[1] == 1  # each other's frame 1, 0.01 apart in the second axis
    np.testing.assert_allclose(err[:2], 0.01)
    assert nn[2] == 2 and err[2] == pytest.approx(np.sqrt(18.0))  # (5, 5): its own is out


def test_puck_paths_stay_clear_of_the_hurdle():
    puck, hand = occlusion.puck_paths(jax.random.PRNGKey(0), "hurdle_top", 32, 50)
    assert puck.shape == hand.shape == (32, 50, 2)
    x, y = puck[..., 0], puck[..., 1]
    # free region for the puck centre (radius 4 cm) and the middle wall x in [.04, .06], y < .62
    assert x.min() >= -0.0351 and x.max() <= 0.1101 and y.min() >= 0.5349 and y.max() <= 0.6701
    in_wall_band = (x > 0.0 + 0.0051) & (x < 0.10 - 0.0051)
    assert np.all(y[in_wall_band] >= 0.66 - 0.0051)
    # the puck moves and the hand touches it from behind
    assert np.all(np.linalg.norm(puck[:, -1] - puck[:, 0], axis=-1) > 0.03)
    np.testing.assert_allclose(np.linalg.norm(puck - hand, axis=-1), occlusion.HAND_BEHIND,
                               rtol=1e-4)
    with pytest.raises(ValueError, match="hurdle"):
        occlusion.puck_paths(jax.random.PRNGKey(0), "door_open", 2, 5)


def test_occlusion_models_train_and_retrieve_tiny():
    """End to end on tiny shapes: untrained object-VAE, two 8-unit LSTMs trained 2 steps each
    (with / without matching loss); three finite errors."""
    from configs.encoders import LSTMConfig, object_vae_config
    from roll_jax.encoders import steps

    rng = np.random.default_rng(4)
    images, masks, pos = _disc_trajectories(4, 4, rng)
    vcfg = object_vae_config("hurdle_top")
    lcfg = LSTMConfig(hidden=8, out_dim=vcfg.latent_dim)
    vae = steps.init_vae(jax.random.PRNGKey(0), vcfg)
    params, hist, snaps = occlusion.train_occlusion_lstms(
        jax.random.PRNGKey(1), vae.params, vcfg, lcfg, images, masks, n_steps=3, batch=3,
        chunk=2, snapshot_steps=(0, 1, 3))
    assert set(hist) == {"lstm_matching", "lstm"}
    assert all(h.shape == (3,) and np.all(np.isfinite(h)) for h in hist.values())
    frame_encoder, heads = occlusion.occlusion_models(vae.params, vcfg, params)
    res = occlusion.occlusion_retrieval(jax.random.PRNGKey(2), images, masks, pos,
                                       frame_encoder, heads)
    assert set(res["error_cm"]) == {"lstm_matching", "lstm", "vae"}
    assert all(np.isfinite(v).all() and v[0] >= 0 for v in res["error_cm"].values())

    # Snapshots: step 0 is the shared initialisation, the last the returned weights, and a
    # step in between is neither (the LSTMs did train).
    leaves = jax.tree.leaves
    for a, b in zip(leaves(snaps[0]["lstm"]), leaves(snaps[0]["lstm_matching"])):
        np.testing.assert_array_equal(a, b)
    for name in ("lstm", "lstm_matching"):
        for a, b in zip(leaves(snaps[3][name]), leaves(params[name])):
            np.testing.assert_array_equal(a, b)
        for other in (snaps[0][name], params[name]):
            assert any(not np.array_equal(a, b) for a, b in zip(leaves(snaps[1][name]),
                                                                leaves(other)))
    # The queries scored once serve every snapshot; the returned weights score as above.
    queries = occlusion.occlusion_queries(jax.random.PRNGKey(2), images, masks, frame_encoder)
    final = occlusion.score_heads(*queries, pos, occlusion.occlusion_models(vae.params, vcfg,
                                                                          snaps[3])[1])
    assert final["error_cm"] == res["error_cm"]
    others = occlusion.score_heads(*queries, pos, occlusion.occlusion_models(vae.params, vcfg,
                                                                           snaps[3])[1],
                                  exclude_own=True)
    row = occlusion.curve_row(3, final, hist, others, final, window=2)
    assert row["lstm_steps"] == 3 and row["loss"]["lstm"] == pytest.approx(hist["lstm"][1:].mean())
    assert row["other_trajectories"]["error_cm"] == others["error_cm"]
    assert row["clean_frames"]["median_cm"] == final["median_cm"]
    assert occlusion.curve_row(0, final, hist)["loss"] == {"lstm_matching": None, "lstm": None}
    with pytest.raises(ValueError, match="snapshot_steps"):
        occlusion.train_occlusion_lstms(jax.random.PRNGKey(1), vae.params, vcfg, lcfg, images,
                                       masks, n_steps=3, batch=3, snapshot_steps=(4,))


def test_ordering_needs_each_step_separated_beyond_two_standard_errors(tmp_path):
    rng = np.random.default_rng(5)
    vae = rng.uniform(2.0, 4.0, 200)
    res = {"errors_cm": {"lstm_matching": vae - 2.0, "lstm": vae - 1.0, "vae": vae}}
    assert occlusion.ordering_holds(res)
    # The auto-encoder LSTM that retrieves what the object-VAE retrieves: not separated.
    res["errors_cm"]["lstm"] = vae + rng.normal(0.0, 0.05, 200)
    assert not occlusion.ordering_holds(res)
    diff = stats.paired_difference(res["errors_cm"]["lstm"], vae)
    assert abs(diff[0]) < 3 * diff[1] and diff[1] == pytest.approx(0.05 / np.sqrt(200), rel=0.2)
    curve = [{"lstm_steps": s, "error_cm": {k: [m, 0.1] for k, m in
                                            zip(occlusion.OCCLUSION_MODELS, (0.6, e, 2.4))}}
             for s, e in ((0, 0.6), (100, 0.9), (2000, 2.4))]
    png = occlusion.write_occlusion_curve(curve, str(tmp_path), "hurdle_top")
    assert os.path.getsize(png) > 1000
