"""U-Net: shapes, parameter tree, BatchNorm modes, learning a synthetic mask, one trace per fit,
the optimizer's arithmetic, input validation."""
import functools

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

from configs.segmentation import SegmentationConfig
from roll_jax.segmentation import unet

F, S = 4, 32  # base width, image size (32 -> 16 -> 8 -> 4 -> 2)
EPOCHS, N_TRAIN, BATCH, N_TEST = 6, 256, 32, 64


def _synthetic(rng, n, s=S):
    """Noisy dark background with one bright random rectangle or ellipse; label = shape pixels."""
    yy, xx = np.mgrid[:s, :s]
    cy, cx = rng.uniform(6, s - 6, (2, n, 1, 1))
    ry, rx = rng.uniform(3, 7, (2, n, 1, 1))
    ellipse = ((yy - cy) / ry) ** 2 + ((xx - cx) / rx) ** 2 < 1
    rect = (np.abs(yy - cy) < ry) & (np.abs(xx - cx) < rx)
    labels = np.where(np.arange(n)[:, None, None] % 2 == 0, rect, ellipse)
    background = rng.normal(60, 25, (n, s, s, 3))
    shape = rng.uniform(150, 255, (n, 1, 1, 3)) + rng.normal(0, 15, (n, s, s, 3))
    images = np.where(labels[..., None], shape, background)
    return np.clip(images, 0, 255).astype(np.uint8), labels


@pytest.fixture(scope="module")
def state():
    return unet.init_unet(jax.random.key(0), F, S, S)


@pytest.fixture(scope="module")
def fitted():
    """One training run shared by the learning, trace-count and augmentation tests."""
    rng = np.random.default_rng(0)
    images, labels = _synthetic(rng, N_TRAIN)
    test_images, test_labels = _synthetic(rng, N_TEST)
    # lr 0.05 instead of the paper's 1e-3: the paper trains ~1900 steps (30 epochs of 2000+
    # frames), this test 48 (measured at 1e-3: held-out IoU 0.66 after 40 steps).
    cfg = SegmentationConfig(unet_features=F, unet_epochs=EPOCHS, unet_lr=0.05,
                             unet_batch_size=BATCH)
    aug_calls = []

    def flip(key, x, y):  # label-preserving random left-right flip, per image
        jax.debug.callback(lambda shape: aug_calls.append(tuple(shape)), jnp.array(x.shape))
        f = jax.random.bernoulli(key, 0.5, (x.shape[0],))
        return (jnp.where(f[:, None, None, None], x[:, :, ::-1], x),
                jnp.where(f[:, None, None], y[:, :, ::-1], y))

    traces = unet.TRACE_COUNTS["fit_unet.epoch"]
    epochs_seen = []
    st, history = unet.fit_unet(jax.random.key(1), images, labels, cfg, augment_fn=flip,
                                progress=lambda e, loss: epochs_seen.append(e))
    jax.effects_barrier()
    prob = np.asarray(unet.robot_probability(st, test_images))
    return {"history": history, "prob": prob, "test_labels": test_labels,
            "traces": unet.TRACE_COUNTS["fit_unet.epoch"] - traces, "aug_calls": aug_calls,
            "epochs_seen": epochs_seen}


# ----------------------------------------------------------------------------- model


def test_output_shapes(state):
    images = _synthetic(np.random.default_rng(1), N_TEST)[0]  # the fit's shape: one compile
    prob = unet.robot_probability(state, images)
    assert prob.shape == (N_TEST, S, S) and prob.dtype == jnp.float32
    assert 0.0 <= float(prob.min()) and float(prob.max()) <= 1.0
    single = unet.robot_probability({"params": state.params, "batch_stats": state.batch_stats},
                                    images[0])
    assert single.shape == (S, S)
    # Eval-mode BatchNorm is per sample: one image alone, batched, or vmapped agree.
    np.testing.assert_allclose(single, prob[0], atol=1e-6)
    vmapped = jax.vmap(unet.robot_probability, (None, 0))(state, images)
    np.testing.assert_allclose(vmapped, prob, atol=1e-6)
    # 48x48 (the env's size) goes 48-24-12-6-3; shapes only, nothing compiled.
    model = unet.UNet(F)
    _, inter = jax.eval_shape(
        lambda v, x: model.apply(v, x, capture_intermediates=True, mutable=["intermediates"]),
        {"params": state.params, "batch_stats": state.batch_stats},
        jax.ShapeDtypeStruct((2, 48, 48, 3), jnp.float32))
    sizes = [inter["intermediates"][name]["__call__"][0].shape[1]
             for name in ("inc", "down1", "down2", "down3", "down4")]
    assert sizes == [48, 24, 12, 6, 3]
    assert inter["intermediates"]["__call__"][0].shape == (2, 48, 48)


def test_parameter_tree(state):
    p = state.params
    assert set(p) == {"inc", "down1", "down2", "down3", "down4", "up1", "up2", "up3", "up4",
                      "outc"}

    def widths(block):  # (in, mid, out) of a double conv
        dc = p[block]["DoubleConv_0"] if block != "inc" else p[block]
        k0, k1 = dc["Conv_0"]["kernel"].shape, dc["Conv_1"]["kernel"].shape
        assert k0[:2] == k1[:2] == (3, 3) and set(dc) == {"Conv_0", "Conv_1", "BatchNorm_0",
                                                          "BatchNorm_1"}
        return k0[2], k0[3], k1[3]

    # milesial bilinear widths: f, 2f, 4f, 8f, 8f down; up convs halve the concatenation.
    assert [widths(b) for b in ("inc", "down1", "down2", "down3", "down4")] == [
        (3, F, F), (F, 2 * F, 2 * F), (2 * F, 4 * F, 4 * F), (4 * F, 8 * F, 8 * F),
        (8 * F, 8 * F, 8 * F)]
    assert [widths(b) for b in ("up1", "up2", "up3", "up4")] == [
        (16 * F, 8 * F, 4 * F), (8 * F, 4 * F, 2 * F), (4 * F, 2 * F, F), (2 * F, F, F)]
    assert p["outc"]["kernel"].shape == (1, 1, F, 1)
    n_bn = len(jax.tree.leaves(state.batch_stats)) // 2  # mean, var per BatchNorm
    assert n_bn == 9 * 2


def test_batchnorm_train_updates_stats_eval_keeps_them(state):
    model = unet.UNet(F)
    variables = {"params": state.params, "batch_stats": state.batch_stats}
    x = jnp.asarray(_synthetic(np.random.default_rng(2), 4)[0], jnp.float32) / 255

    @jax.jit
    def run(variables, x):
        _, train = model.apply(variables, x, train=True, mutable=["batch_stats"])
        _, evaled = model.apply(variables, x, train=False, mutable=["batch_stats"])
        return train["batch_stats"], evaled["batch_stats"]

    train_stats, eval_stats = run(variables, x)
    old = jax.tree.leaves(state.batch_stats)
    assert all(not np.allclose(a, b) for a, b in zip(jax.tree.leaves(train_stats), old))
    assert all(np.array_equal(a, b) for a, b in zip(jax.tree.leaves(eval_stats), old))
    # PyTorch momentum 0.1: new = 0.9 old + 0.1 batch (fresh var is 1, batch var >= 0).
    var = train_stats["inc"]["BatchNorm_0"]["var"]
    assert np.all(var >= 0.9 - 1e-6)


@pytest.mark.parametrize("k", [3, 1])
@pytest.mark.parametrize("cin,cout", [(3, 5), (5, 3)])  # input taps / output-gradient taps
def test_conv_dot_wgrad_matches_autodiff(k, cin, cout):
    rng = np.random.default_rng(3)  # numpy data: a jax.random draw compiles per shape
    x = rng.standard_normal((2, 16, 12, cin), dtype=np.float32)
    kernel = rng.standard_normal((k, k, cin, cout), dtype=np.float32)
    g = rng.standard_normal((2, 16, 12, cout), dtype=np.float32)

    @jax.jit
    def both(x, kernel):
        def vjp(f):
            y, pull = jax.vjp(f, x, kernel)
            return y, pull(g)
        return vjp(unet.conv_dot_wgrad), vjp(unet._conv)

    (y, (dx, dk)), (y_ref, (dx_ref, dk_ref)) = both(x, kernel)
    np.testing.assert_allclose(y, y_ref, atol=1e-5)
    np.testing.assert_allclose(dx, dx_ref, rtol=1e-5, atol=1e-4)
    np.testing.assert_allclose(dk, dk_ref, rtol=1e-5, atol=1e-3)


def test_max_pool_matches_flax():
    x = np.random.default_rng(6).standard_normal((2, 8, 8, 3), dtype=np.float32)
    np.testing.assert_array_equal(unet._max_pool2(x), nn.max_pool(x, (2, 2), strides=(2, 2)))


# ----------------------------------------------------------------------------- optimization


def test_optimizer_is_nesterov_sgd_with_weight_decay():
    lr, mu, wd = 0.1, 0.5, 0.01
    tx = unet.make_optimizer(SegmentationConfig(unet_lr=lr, unet_momentum=mu,
                                                unet_weight_decay=wd))
    p = {"w": jnp.array([1.0, -2.0])}
    grads = [np.array([0.3, 0.4]), np.array([-1.0, 0.2])]
    opt_state = tx.init(p)
    # PyTorch SGD(nesterov=True, weight_decay=wd) by hand: d = g + wd p; v = mu v + d;
    # p -= lr (d + mu v).
    w, v = np.array([1.0, -2.0]), np.zeros(2)
    for g in grads:
        updates, opt_state = tx.update({"w": jnp.asarray(g)}, opt_state, p)
        p = optax.apply_updates(p, updates)
        d = g + wd * w
        v = mu * v + d
        w = w - lr * (d + mu * v)
        np.testing.assert_allclose(p["w"], w, rtol=1e-6)
    # The second step differs from plain momentum and from no weight decay: all three are used.
    assert not np.allclose(w, [1.0, -2.0] - lr * np.sum(grads, 0))


def test_bce_loss():
    logits = jnp.array([[0.0, 2.0], [-1.0, 3.0]])
    labels = jnp.array([[1.0, 0.0], [0.0, 1.0]])
    ref = np.mean(np.logaddexp(0, logits) - labels * logits)
    np.testing.assert_allclose(unet.bce_loss(logits, labels), ref, rtol=1e-6)
    w = jnp.array([[1.0, 0.0], [0.0, 0.0]])
    np.testing.assert_allclose(unet.bce_loss(logits, labels, w), np.log(2) / 4, rtol=1e-6)


def test_train_step_structure(state):
    # Values are exercised by the fit (train_step is its scan body); here shapes only, so no
    # extra ~15-20 s compile of a top-level training step.
    images, labels = _synthetic(np.random.default_rng(7), 4)
    step = functools.partial(unet.train_step, cfg=SegmentationConfig(unet_features=F))
    new, metrics = jax.eval_shape(step, state, images, labels)
    assert jax.tree.structure(new) == jax.tree.structure(state)
    assert all(a.shape == b.shape and a.dtype == b.dtype
               for a, b in zip(jax.tree.leaves(new), jax.tree.leaves(state)))
    assert {k: (v.shape, v.dtype) for k, v in metrics.items()} == {
        "loss": ((), jnp.float32), "accuracy": ((), jnp.float32)}


def test_learns_synthetic_mask(fitted):
    history, prob, labels = fitted["history"], fitted["prob"], fitted["test_labels"]
    pred = prob > 0.5
    iou = (pred & labels).sum((1, 2)) / np.maximum((pred | labels).sum((1, 2)), 1)
    # Measured (6 epochs of 8 batches, features=4, CPU): epoch-mean loss 0.48 -> 0.028,
    # held-out mean IoU 0.92 (worst image 0.82); another data/key seed: 0.49 -> 0.020, IoU 0.97.
    # The bars (loss halved, IoU > 0.8) leave room for other seeds and backends.
    assert history[-1] < 0.5 * history[0], history
    assert iou.mean() > 0.8, iou.mean()
    assert fitted["epochs_seen"] == list(range(EPOCHS))


def test_epoch_traced_once_and_augment_runs_per_batch(fitted):
    assert fitted["traces"] == 1
    assert fitted["aug_calls"] == [(BATCH, S, S, 3)] * (EPOCHS * (N_TRAIN // BATCH))


# ----------------------------------------------------------------------------- validation


def test_bad_inputs_raise(state):
    cfg = SegmentationConfig(unet_features=F, unet_epochs=1, unet_batch_size=8)
    key = jax.random.key(0)
    imgs, labels = _synthetic(np.random.default_rng(8), 4)
    with pytest.raises(ValueError, match=r"expected uint8 images \[N, H, W, 3\], got float32 "
                                         r"\[4, 32, 32, 3\]"):
        unet.fit_unet(key, imgs.astype(np.float32), labels, cfg)
    with pytest.raises(ValueError, match=r"got uint8 \[4, 32, 32, 1\]"):
        unet.fit_unet(key, imgs[..., :1], labels, cfg)
    with pytest.raises(ValueError, match=r"got uint8 \[4, 32, 32\]"):
        unet.train_step(state, imgs[..., 0], labels, cfg)
    with pytest.raises(ValueError, match=r"multiples of 16.*got 24x32"):
        unet.robot_probability(state, imgs[:, :24])
    with pytest.raises(ValueError, match=r"labels \[N, H, W\] = \[4, 32, 32\].*got bool \[4, 32\]"):
        unet.fit_unet(key, imgs, labels[:, 0], cfg)
    with pytest.raises(ValueError, match=r"4 training images is fewer than unet_batch_size=8"):
        unet.fit_unet(key, imgs, labels, cfg)
    with pytest.raises(ValueError, match=r"UNetState or variables"):
        unet.robot_probability(state.params, imgs)
    with pytest.raises(ValueError, match=r"expected uint8 images \[H, W, 3\] or \[N, H, W, 3\], "
                                         r"got float32"):
        unet.robot_probability(state, imgs.astype(np.float32))

    def bad_augment(key, x, y):
        return x.astype(jnp.float32), y

    cfg4 = SegmentationConfig(unet_features=F, unet_epochs=1, unet_batch_size=4)
    with pytest.raises(ValueError, match=r"augment_fn must return uint8 images"):
        unet.fit_unet(key, imgs, labels, cfg4, augment_fn=bad_augment, init_state=state)
