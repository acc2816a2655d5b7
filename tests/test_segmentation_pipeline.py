"""The segmentation pipeline end to end on puck_push: fit on empty-scene frames, then
segment rendered scenes with a puck."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import envs_mjx
from configs.segmentation import segmentation_config
from roll_jax.segmentation import mog2, pipeline

# Small enough for CPU CI, large enough to learn the arm: 600 frames from 30 random walks,
# 8 epochs of a width-8 U-Net at 10x the paper's learning rate (few steps here). Measured:
# IoU 0.84, robot leakage 5% (the paper preset does better; see docs/segmentation.md).
CFG = segmentation_config("puck_push", "smoke", n_frames=600, n_envs=30, unet_epochs=8,
                          eval_states=48, unet_lr=1e-2, unet_batch_size=16)


@pytest.fixture(scope="module")
def fitted():
    env = envs_mjx.make("puck_push")
    params, info = pipeline.fit(env, jax.random.PRNGKey(0), CFG)
    return env, params, info


def test_robot_labels_come_from_the_background_model(fitted):
    _env, params, info = fitted
    frames, robot = np.asarray(info["frames"]), np.asarray(info["robot_labels"])
    assert frames.shape == (CFG.n_frames, 48, 48, 3) and frames.dtype == np.uint8
    # The arm moves, so a few % of pixels are foreground, not none and not everything.
    assert 0.01 < robot.mean() < 0.3
    # Where the frozen model never saw foreground, the background image is the scene as
    # every frame shows it (a pixel may hold several background modes, e.g. the arm's base
    # edge, so allow a small share of exceptions).
    bg = np.asarray(mog2.background_image(params.background)).astype(int)
    never_robot = ~robot.any(0)
    close = np.abs(bg - frames.astype(int)).max(-1) <= 2  # [N, H, W]
    assert close[:, never_robot].mean() > 0.95


def test_lower_label_background_ratio_labels_more_of_the_arm(fitted):
    _env, params, info = fitted
    frames = info["frames"]
    at_09 = np.asarray(pipeline.robot_labels(params.background, frames, 0.9))
    at_05 = np.asarray(pipeline.robot_labels(params.background, frames, 0.5))
    np.testing.assert_array_equal(at_09, np.asarray(info["robot_labels"]))  # the config's 0.9
    assert (at_09 <= at_05).all() and at_05.sum() > at_09.sum()  # a superset, strictly larger
    assert params.background.background_ratio == np.float32(0.9)  # segment keeps OpenCV's
    with pytest.raises(ValueError, match="label_background_ratio"):
        segmentation_config("door_open", label_background_ratio=0.0)


def test_mog2_parity_with_cv2_on_the_rendered_scene(fitted):
    """The pipeline's own use, on rendered frames: fit at lr -1 on the empty-scene walks
    (history = their number), then lr 0 on states with the puck; cv2 must agree pixel for
    pixel on every frame, shadows on and off, and the fitted model must be the pipeline's."""
    from roll_jax.segmentation import mog2_parity as mp

    env, params, info = fitted
    scene, _ = pipeline.random_object_states(env, jax.random.PRNGKey(4), 40)
    frames = np.concatenate([np.asarray(info["frames"]), scene])
    lrs = np.where(np.arange(len(frames)) < CFG.n_frames, -1.0, 0.0)
    runs = {}
    for shadows in (True, False):
        r = runs[shadows] = mp.compare(frames, lrs, history=CFG.n_frames, detect_shadows=shadows)
        assert r.min == 1.0, (shadows, np.flatnonzero(r.agreement < 1)[:10])
        assert r.background_equal == 1.0
        assert (r.cv2_masks[CFG.n_frames:] == 255).any()  # the puck and arm are foreground
    # With shadows on (the config) cv2's lr-0 masks, shadows counted, are `segment`'s
    # foreground from the pipeline's fitted model.
    fg = np.asarray(mog2.frozen_foreground(params.background, jnp.asarray(scene)))
    np.testing.assert_array_equal(fg, runs[True].cv2_masks[CFG.n_frames:] > 0)


def test_unet_loss_falls(fitted):
    _, _, info = fitted
    loss = np.asarray(info["unet_loss"])
    assert loss[-1] < 0.5 * loss[0], loss


def test_segment_keeps_puck_and_drops_arm(fitted):
    env, params, _ = fitted
    summary, _arrays = pipeline.evaluate(env, params, jax.random.PRNGKey(1), CFG.eval_states)
    # Bars: a perfect robot mask gives IoU 1.0 here (MOG2 alone finds every puck pixel and no
    # background); without the U-Net the object mask keeps ~78% of the robot pixels and IoU
    # falls to ~0.4. 0.75 / 10% leave room for the tiny CI-sized U-Net and still fail if the
    # arm is not removed.
    assert summary["n_states"] == CFG.eval_states
    assert summary["iou"] > 0.75, summary
    assert summary["robot_leakage"] < 0.10, summary
    assert summary["background_leakage"] < 0.01, summary


def test_segment_is_jittable_and_batched(fitted):
    env, params, _ = fitted
    rgb, _ = pipeline.random_object_states(env, jax.random.PRNGKey(2), 6)
    m1 = jax.jit(pipeline.segment)(params, rgb.reshape(2, 3, 48, 48, 3))
    m2 = pipeline.segment(params, rgb)
    assert m1.shape == (2, 3, 48, 48) and m1.dtype == jnp.bool_
    np.testing.assert_array_equal(np.asarray(m1).reshape(6, 48, 48), np.asarray(m2))
    seg = pipeline.segmented_image(rgb, m2)
    assert (np.asarray(seg)[~np.asarray(m2)] == 0).all()
    # Any number of states runs in whole chunks of one compiled program: 40 and 80
    # (`evaluate`) above, 6 and 4 here, all one program for the env.
    rgb4, _ = pipeline.random_object_states(env, jax.random.PRNGKey(2), 4)
    np.testing.assert_array_equal(rgb4, rgb[:4])  # state i depends on the key and i only
    assert pipeline._object_states_fn(env, 5, False, "random")._cache_size() == 1


def test_segment_rejects_bad_images(fitted):
    _, params, _ = fitted
    with pytest.raises(ValueError, match=r"expected uint8 images \[\.\.\., 48, 48, 3\], got float32"):
        pipeline.segment(params, jnp.zeros((2, 48, 48, 3), jnp.float32))
    with pytest.raises(ValueError, match=r"got uint8 \[2, 48, 48, 1\]"):
        pipeline.segment(params, jnp.zeros((2, 48, 48, 1), jnp.uint8))
    with pytest.raises(ValueError, match=r"got uint8 \[32, 32, 3\]"):
        pipeline.segment(params, jnp.zeros((32, 32, 3), jnp.uint8))


def test_checkpoint_roundtrip_and_refusals(fitted, tmp_path):
    env, params, _ = fitted
    pipeline.save(str(tmp_path / "seg"), "puck_push", params, CFG)
    restored, cfg = pipeline.load(str(tmp_path / "seg"), "puck_push")
    assert cfg == CFG
    rgb, _ = pipeline.random_object_states(env, jax.random.PRNGKey(3), 4)
    np.testing.assert_array_equal(pipeline.segment(params, rgb), pipeline.segment(restored, rgb))
    with pytest.raises(ValueError, match="fitted for task 'puck_push', not 'door_open'"):
        pipeline.load(str(tmp_path / "seg"), "door_open")
    with pytest.raises(ValueError, match=r"is for images \[48, 48, 3\], not \[64, 64, 3\]"):
        pipeline.load(str(tmp_path / "seg"), "puck_push", image_shape=(64, 64, 3))


def test_distractors_are_not_robot():
    images = jnp.zeros((64, 48, 48, 3), jnp.uint8)
    labels = jnp.ones((64, 48, 48), jnp.float32)
    out, lab = pipeline.paste_distractors(jax.random.PRNGKey(0), images, labels, 1.0)
    changed = np.asarray((out != images).any(-1))
    assert changed.any(axis=(1, 2)).mean() > 0.9  # (a few blobs are black like the image)
    # Wherever a blob was pasted, the label says not-robot; elsewhere it is untouched.
    assert (np.asarray(lab)[changed] == 0).all()
    blob_px = (np.asarray(lab) == 0).sum((1, 2))
    assert blob_px.min() >= 1 and blob_px.max() < 48 * 48 / 4


def test_distractors_near_robot_cover_the_robot():
    images = jnp.zeros((32, 48, 48, 3), jnp.uint8)
    robot = np.zeros((32, 48, 48), np.float32)
    robot[:, 40:44, 2:6] = 1.0  # a small "arm" in a corner
    robot[-1] = 0.0  # no robot pixel: falls back to anywhere
    robot = jnp.asarray(robot)
    _, lab = pipeline.paste_distractors(jax.random.PRNGKey(1), images, robot, 1.0,
                                        near_robot=1.0, max_radius=3.0)
    lab = np.asarray(lab)
    # Every blob is centred on an arm pixel, so each image lost some of its arm labels.
    assert (lab[:-1, 40:44, 2:6] == 0).any(axis=(1, 2)).all()
    with pytest.raises(ValueError, match="distractor_near_robot"):
        segmentation_config("door_open", distractor_near_robot=1.5)


def test_distractors_behind_robot_keep_the_robot():
    images = jnp.zeros((32, 48, 48, 3), jnp.uint8)
    robot = np.zeros((32, 48, 48), np.float32)
    robot[:, 20:28, 20:28] = 1.0
    robot = jnp.asarray(robot)
    out, lab = pipeline.paste_distractors(jax.random.PRNGKey(2), images, robot, 1.0,
                                          near_robot=1.0, max_radius=8.0, behind_robot=1.0)
    out, lab = np.asarray(out), np.asarray(lab)
    # The arm keeps its pixels and labels; the blob shows around it.
    np.testing.assert_array_equal(lab, np.asarray(robot))
    assert (out[:, 20:28, 20:28] == 0).all()
    assert (out != 0).any(-1).any((1, 2)).mean() > 0.8
    with pytest.raises(ValueError, match="distractor_behind_robot"):
        segmentation_config("door_open", distractor_behind_robot=-0.1)
