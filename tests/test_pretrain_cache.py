"""The pre-training cache of the reproduction grid (`pretrain.pretrain(cache=DIR)`): a run
with the same spec loads the datasets and models an earlier run built (bit-identical), an
ablation rebuilds exactly the models its config changes, and another segmentation means
other object data. Synthetic images stand in for the rendered datasets (what is tested is
which parts are built or loaded; the training itself is the real code path)."""

import dataclasses
import os

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from configs.train import make_config
from roll_jax.encoders import pretrain


def tiny(arm_pair_coef=0.0, **flags):
    base = make_config("puck_push", "roll", "smoke", **flags)
    small = {"epochs": 1, "batches_per_epoch": 2, "batch_size": 4, "n_pretrain_images": 12}
    return make_config("puck_push", "roll", "smoke", **flags,
                       scene_vae=dataclasses.replace(base.scene, **small),
                       object_vae=dataclasses.replace(base.object_vae, **small,
                                                      arm_pair_coef=arm_pair_coef),
                       lstm=dataclasses.replace(base.lstm, epochs=1, batches_per_epoch=1,
                                                batch_size=2))


@pytest.fixture()
def built(monkeypatch):
    """Counts what is built; the datasets are random images of the right shape."""
    counts = {"scene_data": 0, "object_data": 0, "vae": 0, "lstm": 0}

    def scene_dataset(env, key, n, source="random_policy"):
        counts["scene_data"] += 1
        return jax.random.randint(key, (n, 48, 48, 3), 0, 256).astype(jnp.uint8)

    def object_dataset(env, seg, key, n, goal_share=0.0, arm_pairs=False, hand="random"):
        counts["object_data"] += 1
        out = ()
        for k in [key, jax.random.fold_in(key, 1)][:1 + arm_pairs]:  # images (and partners)
            masks = jax.random.bernoulli(k, 0.1, (n, 48, 48))
            out += (jnp.where(masks[..., None], jnp.full((n, 48, 48, 3), 200, jnp.uint8), 0),
                    masks)
        return out

    fit_vae, fit_lstm = pretrain._fit_vae, pretrain._fit_lstm

    def count(name, fn):
        def wrapped(*a, **kw):
            counts[name] += 1
            return fn(*a, **kw)
        return wrapped

    monkeypatch.setattr(pretrain, "scene_dataset", scene_dataset)
    monkeypatch.setattr(pretrain, "object_dataset", object_dataset)
    monkeypatch.setattr(pretrain, "_fit_vae", count("vae", fit_vae))
    monkeypatch.setattr(pretrain, "_fit_lstm", count("lstm", fit_lstm))
    return counts


def _equal(a, b):
    return all(np.array_equal(x, y) for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b)))


def test_cache_shares_what_matches_and_rebuilds_the_rest(built, tmp_path):
    cache, key, seg = str(tmp_path / "pretrain"), jax.random.PRNGKey(3), {"w": jnp.ones(3)}
    first, info = pretrain.pretrain(tiny(), None, seg, key, progress=False, cache=cache)
    assert built == {"scene_data": 1, "object_data": 1, "vae": 2, "lstm": 1}
    assert len([f for f in os.listdir(cache) if f.endswith(".npz")]) == 5
    # The same spec again (another run of the grid): everything loaded, bit-identical.
    again, info2 = pretrain.pretrain(tiny(), None, seg, key, progress=False, cache=cache)
    assert built == {"scene_data": 1, "object_data": 1, "vae": 2, "lstm": 1}
    assert _equal(first, again) and info2["scene_loss"] == info["scene_loss"]
    assert "scene_data" not in info2  # no model needed the images: they were not even loaded
    # No matching loss: same scene-VAE and object data; the object-VAE (its loss changed)
    # and the LSTM on top of it are trained anew.
    abl, _ = pretrain.pretrain(tiny(matching_loss=False), None, seg, key, progress=False,
                               cache=cache)
    assert built == {"scene_data": 1, "object_data": 1, "vae": 3, "lstm": 2}
    assert _equal(abl.scene_vae, first.scene_vae)
    assert not _equal(abl.object_vae.params, first.object_vae.params)
    # Another segmentation: other object data; without a cache nothing is shared.
    pretrain.pretrain(tiny(), None, {"w": jnp.zeros(3)}, key, progress=False, cache=cache)
    assert built["object_data"] == 2 and built["scene_data"] == 1
    fresh, _ = pretrain.pretrain(tiny(), None, seg, key, progress=False)
    assert built["scene_data"] == 2 and _equal(fresh, first)
    # The arm-pair loss: object data with partners and an object-VAE trained on them, built
    # once; the second run loads both (partners included), bit-identical.
    before = dict(built)
    paired, _ = pretrain.pretrain(tiny(arm_pair_coef=1.0), None, seg, key, progress=False,
                                  cache=cache)
    grew = {k: built[k] - before[k] for k in built}
    assert grew == {"scene_data": 0, "object_data": 1, "vae": 1, "lstm": 1}
    assert _equal(paired.scene_vae, first.scene_vae)
    assert not _equal(paired.object_vae.params, first.object_vae.params)
    again, _ = pretrain.pretrain(tiny(arm_pair_coef=1.0), None, seg, key, progress=False,
                                 cache=cache)
    assert built == {k: before[k] + grew[k] for k in built} and _equal(again, paired)


def test_scene_data_from_goals_are_rendered_goal_states():
    import envs_mjx

    env = envs_mjx.make("puck_push")
    key = jax.random.PRNGKey(3)
    data = pretrain.scene_dataset(env, key, 4, "goals")
    want = jax.jit(jax.vmap(lambda k: env.render(env.sample_goal(k))))(jax.random.split(key, 4))
    np.testing.assert_array_equal(data, want)
    assert data.shape == (4, 48, 48, 3) and data.dtype == jnp.uint8
    assert len({np.asarray(x).tobytes() for x in data}) == 4  # four different goal states
    with pytest.raises(ValueError, match="'random_policy', 'goals', 'region' or 'placements', got 'expert'"):
        pretrain.scene_dataset(env, key, 4, "expert")


def test_scene_data_from_placements_spread_the_hand_and_the_door():
    import envs_mjx

    env = envs_mjx.make("door_open")
    key = jax.random.PRNGKey(4)
    data = pretrain.scene_dataset(env, key, 6, "placements")
    states = jax.vmap(lambda k: env.random_placement(*jax.random.split(k)))(
        jax.random.split(key, 6))
    np.testing.assert_array_equal(data, jax.vmap(env.render)(states))
    hand, angle = np.asarray(jax.vmap(env.hand_pos)(states)), np.asarray(
        jax.vmap(env.object_state)(states))[:, 0]
    # the hand anywhere in its box (not at the handle, as in the goal images), the door at
    # angles over its range
    assert np.ptp(hand, 0).min() > 0.02 and np.ptp(angle) > 0.2
    assert len({np.asarray(x).tobytes() for x in data}) == 6


def test_object_data_holds_the_configured_share_of_goal_states():
    import envs_mjx
    from configs.encoders import object_vae_config
    from configs.segmentation import segmentation_config
    from roll_jax.segmentation import pipeline

    env = envs_mjx.make("puck_push")
    # An unfitted background model and a threshold the U-Net never passes: the mask keeps
    # every pixel, so the segmented images are the rendered ones.
    seg = pipeline.initial_params(48, 48, 3, segmentation_config("puck_push", "smoke"))
    seg = seg.replace(robot_threshold=jnp.float32(2.0))
    key = jax.random.PRNGKey(5)
    images, masks = pretrain.object_dataset(env, seg, key, 4, goal_share=0.5)
    assert images.shape == (4, 48, 48, 3) and bool(masks.all())
    k_place, k_goal = jax.random.split(key)
    goals = pretrain._goal_images_fn(env)(jax.random.split(k_goal, 2))
    np.testing.assert_array_equal(images[:2], goals)
    placed, _ = pipeline.random_object_states(env, k_place, 2, settle_steps=0)
    np.testing.assert_array_equal(images[2:], placed)
    only_placed, _ = pretrain.object_dataset(env, seg, k_place, 2)
    np.testing.assert_array_equal(only_placed, placed)  # share 0: placements from the key

    # Arm pairs: the same images and masks, and partners that show each placement's object
    # state with the hand elsewhere (a goal image is its own partner).
    a, ma, b, mb = pretrain.object_dataset(env, seg, key, 4, goal_share=0.5, arm_pairs=True)
    np.testing.assert_array_equal(a, images)
    np.testing.assert_array_equal(ma, masks)
    np.testing.assert_array_equal(b[:2], goals)
    rgb, lab, rgb_b, lab_b = pipeline.random_object_states(env, k_place, 2, settle_steps=0,
                                                           arm_pairs=True)
    np.testing.assert_array_equal(rgb, placed)
    np.testing.assert_array_equal(b[2:], rgb_b)
    assert bool(mb.all())
    # The same object: its pixels agree wherever neither arm covers them; the arm moved.
    obj, obj_b, arm, arm_b = lab == 2, lab_b == 2, lab == 1, lab_b == 1
    assert obj.any(axis=(1, 2)).all()
    np.testing.assert_array_equal(obj & ~arm_b, obj_b & ~arm)
    assert all(not np.array_equal(arm[i], arm_b[i]) for i in range(2))
    with pytest.raises(ValueError, match="pretrain_goal_share must be in \\[0, 1\\], got 1.2"):
        object_vae_config("pickup", pretrain_goal_share=1.2)


def test_occlude_share_drops_pixels_of_about_that_share_of_images():
    n = 400
    yy, xx = np.mgrid[0:48, 0:48]
    disc = (yy - 24) ** 2 + (xx - 24) ** 2 <= 36
    masks = jnp.broadcast_to(jnp.asarray(disc), (n, 48, 48))
    images = jnp.where(masks[..., None], jnp.uint8(180), jnp.uint8(0))
    out, out_masks = pretrain.occlude_share(jax.random.PRNGKey(0), images, masks, 0.3, 0.5)
    out, out_masks, images = np.asarray(out), np.asarray(out_masks), np.asarray(images)
    changed = np.any(out != images, axis=(1, 2, 3))
    assert 0.22 < changed.mean() < 0.38
    np.testing.assert_array_equal(out[~changed], images[~changed])
    assert np.all((out == images) | (out == 0))  # pixels are only dropped
    kept = out_masks[changed].sum((1, 2)) / disc.sum()
    assert 0.35 < kept.mean() < 0.65
    np.testing.assert_array_equal(out_masks, np.any(out != 0, axis=-1))  # the pixels left
    same, _ = pretrain.occlude_share(jax.random.PRNGKey(0), images, masks, 0.0, 0.5)
    np.testing.assert_array_equal(same, images)


def test_object_data_holds_the_reference_share_of_occluded_images(built, tmp_path):
    from configs.encoders import object_vae_config

    assert [object_vae_config(t).pretrain_occluded_fraction for t in
            ("puck_push", "hurdle_bottom", "hurdle_top", "door_open", "pickup")] == [
        0.3, 0.3, 0.3, 0.0, 0.0]
    with pytest.raises(ValueError, match="pretrain_occluded_fraction must be in \\[0, 1\\], got 1.5"):
        object_vae_config("puck_push", pretrain_occluded_fraction=1.5)
    cache, key, seg = str(tmp_path / "pretrain"), jax.random.PRNGKey(3), {"w": jnp.ones(3)}
    cfg = tiny()
    clean = dataclasses.replace(cfg, object_vae=dataclasses.replace(
        cfg.object_vae, pretrain_occluded_fraction=0.0))
    _, info = pretrain.pretrain(cfg, None, seg, key, progress=False, cache=cache)
    _, info0 = pretrain.pretrain(clean, None, seg, key, progress=False, cache=cache)
    assert built["object_data"] == 2  # the share is part of the object data's cache key
    occ, base = np.asarray(info["object_data"]), np.asarray(info0["object_data"])
    changed = np.any(occ != base, axis=(1, 2, 3))
    assert 0 < changed.sum() < len(base)  # 12 images at 0.3: some, not all
    assert np.all((occ == base) | (occ == 0))
