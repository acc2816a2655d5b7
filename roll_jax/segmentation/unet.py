"""Robot-segmentation U-Net (paper appendix "Details on unknown object segmentation").

Architecture as in the appendix: an input double-conv block, 4 down blocks (2x2 max-pool, then
two 3x3 stride-1 'SAME' convs each followed by BatchNorm and ReLU), 4 up blocks (bilinear x2
upsampling, concatenation with the matching down level's output, two conv+BN+ReLU) and a 1x1
conv to one logit. Widths follow milesial/Pytorch-UNet's bilinear variant (f, 2f, 4f, 8f, 8f;
up blocks halve the concatenated width in their first conv), BatchNorm uses PyTorch's momentum
0.1 / eps 1e-5. Trained with per-pixel BCE and Nesterov SGD with weight decay (appendix B.1).

Everything here is pure: ``UNetState`` is a pytree, ``train_step`` / ``robot_probability`` are
jittable, and ``fit_unet`` runs one jitted ``lax.scan`` per epoch (it traces once per fit).
"""
from __future__ import annotations

import collections
import functools
from collections.abc import Callable, Mapping
from typing import Any

import flax.linen as nn
import flax.struct
import jax
import jax.numpy as jnp
import numpy as np
import optax
from jax import lax

from configs.segmentation import SegmentationConfig
from roll_jax.common import conv

# Python-side trace counters: a traced body increments its entry once per compilation.
TRACE_COUNTS: collections.Counter = collections.Counter()

_DIVISOR = 16  # 4 max-pools of 2x2


# ----------------------------------------------------------------------------- model


_DN = ("NHWC", "HWIO", "NHWC")


def _conv(x, kernel):
    return lax.conv_general_dilated(x, kernel, (1, 1), "SAME", dimension_numbers=_DN)


@jax.custom_vjp
def conv_dot_wgrad(x, kernel):
    """Stride-1 'SAME' conv (odd kernel) whose kernel gradient is k*k dots, not a conv.

    On CPU, XLA's kernel-gradient convolution inside a while loop (the epoch's ``lax.scan``)
    runs ~10x slower than at top level (measured on a 2-conv toy: 0.24 s vs 0.02 s per step;
    a features=4 U-Net epoch of 8 batches of 32x32x32: 3.6 s vs 0.5 s), while forward convs,
    the input gradient (a forward conv with the flipped kernel) and dots are unaffected.
    Values equal ``lax`` autodiff (tested).
    """
    return _conv(x, kernel)


def _conv_fwd(x, kernel):
    return _conv(x, kernel), (x, kernel)


def tap_weight_gradients(a, taps) -> list:
    """Each tap's sum over rows of ``tap [..., K]`` outer ``a [..., N]`` -> [K, N], as ``a^T tap``
    with ``a`` transposed once for all taps (conv.weight_gradient: XLA:CPU would otherwise
    transpose each tap and run a slower dot form; docs/segmentation.md)."""
    a_t = conv.transposed_rows(a)
    return [conv.weight_gradient(a_t, t) for t in taps]


def conv_backward(res, g, tap_gradients=tap_weight_gradients, shift_output: bool | None = None):
    """(dx, dkernel) of `conv_dot_wgrad`: the input gradient as a conv with the flipped kernel;
    the kernel gradient by `tap_gradients` from the k*k shifted slices of the output gradient
    (``shift_output``) or of the input; None: of the thinner of the two (slicing copies them,
    the thinner copies less: -11% on the width-8 U-Net's train step, docs/segmentation.md).

    Tap (i, j) of the kernel gradient is ``sum_y x[y + d] g[y]`` with ``d = (i, j) - k // 2`` and
    zeros outside the image, which is also ``sum_z x[z] g[z - d]``: either ``x`` or ``g`` can
    be the shifted operand.
    """
    x, kernel = res
    k, h, w = kernel.shape[0], x.shape[1], x.shape[2]
    cin, cout = kernel.shape[2], kernel.shape[3]
    dx = _conv(g, jnp.flip(kernel, (0, 1)).swapaxes(2, 3))
    p = k // 2
    pad = ((0, 0), (p, p), (p, p), (0, 0))
    shift = cout < cin if shift_output is None else shift_output
    if shift:
        gp = jnp.pad(g, pad)
        taps = [gp[:, 2 * p - i:2 * p - i + h, 2 * p - j:2 * p - j + w]
                for i in range(k) for j in range(k)]
        dk = [t.T for t in tap_gradients(x, taps)]  # [Cout, Cin] -> [Cin, Cout]
    else:
        xp = jnp.pad(x, pad)
        taps = [xp[:, i:i + h, j:j + w] for i in range(k) for j in range(k)]
        dk = tap_gradients(g, taps)
    return dx, jnp.stack(dk).reshape(kernel.shape)


conv_dot_wgrad.defvjp(_conv_fwd, conv_backward)


class Conv(nn.Module):
    """Stride-1 'SAME' conv with ``nn.Conv``'s parameters (kernel [k, k, in, out], lecun init).

    ``dot_wgrad``: use ``conv_dot_wgrad`` (see there); ``None`` = on the CPU backend only, GPUs
    keep their native convolution gradients. Forward values are identical either way.
    """

    features: int
    kernel_size: int = 3
    use_bias: bool = True
    dot_wgrad: bool | None = None

    @nn.compact
    def __call__(self, x):
        k, c = self.kernel_size, x.shape[-1]
        kernel = self.param("kernel", nn.initializers.lecun_normal(), (k, k, c, self.features))
        dot_wgrad = jax.default_backend() == "cpu" if self.dot_wgrad is None else self.dot_wgrad
        y = conv_dot_wgrad(x, kernel) if dot_wgrad else _conv(x, kernel)
        if self.use_bias:
            y = y + self.param("bias", nn.initializers.zeros_init(), (self.features,))
        return y


def _max_pool2(x):
    # 2x2/2 max-pool as a reshape + max (H, W are even here): same values as nn.max_pool, and
    # its gradient skips reduce_window/select_and_scatter (2.7x faster fwd+bwd on CPU, measured).
    b, h, w, c = x.shape
    return x.reshape(b, h // 2, 2, w // 2, 2, c).max(axis=(2, 4))


class DoubleConv(nn.Module):
    """(3x3 conv -> BatchNorm -> ReLU) x 2; ``mid_features`` is the first conv's width."""

    features: int
    mid_features: int | None = None
    dot_wgrad: bool | None = None

    @nn.compact
    def __call__(self, x, train: bool):
        for width in (self.mid_features or self.features, self.features):
            # No conv bias: the following BatchNorm's shift makes it redundant.
            x = Conv(width, 3, use_bias=False, dot_wgrad=self.dot_wgrad)(x)
            # PyTorch BatchNorm2d defaults (momentum 0.1 == flax decay 0.9), as in the paper's code.
            x = nn.BatchNorm(use_running_average=not train, momentum=0.9, epsilon=1e-5)(x)
            x = nn.relu(x)
        return x


class Down(nn.Module):
    """2x2 max-pool, then a double conv."""

    features: int
    dot_wgrad: bool | None = None

    @nn.compact
    def __call__(self, x, train: bool):
        return DoubleConv(self.features, dot_wgrad=self.dot_wgrad)(_max_pool2(x), train)


class Up(nn.Module):
    """Bilinear x2 upsampling, concatenation with the skip feature, double conv."""

    features: int
    dot_wgrad: bool | None = None

    @nn.compact
    def __call__(self, x, skip, train: bool):
        # To the skip's size (x2 here, as H, W are multiples of 16).
        x = jax.image.resize(x, skip.shape[:3] + x.shape[3:], method="bilinear")
        x = jnp.concatenate([skip, x], axis=-1)
        return DoubleConv(self.features, x.shape[-1] // 2, self.dot_wgrad)(x, train)


class UNet(nn.Module):
    """float32 [B, H, W, 3] in [0, 1] (H, W divisible by 16) -> robot logits [B, H, W]."""

    features: int = 64
    dot_wgrad: bool | None = None  # see ``Conv``; parameters are the same either way

    @nn.compact
    def __call__(self, x, train: bool = False):
        f, dw = self.features, self.dot_wgrad
        x1 = DoubleConv(f, dot_wgrad=dw, name="inc")(x, train)
        x2 = Down(2 * f, dw, name="down1")(x1, train)
        x3 = Down(4 * f, dw, name="down2")(x2, train)
        x4 = Down(8 * f, dw, name="down3")(x3, train)
        x5 = Down(8 * f, dw, name="down4")(x4, train)  # bilinear variant: bottleneck stays at 8f
        y = Up(4 * f, dw, name="up1")(x5, x4, train)
        y = Up(2 * f, dw, name="up2")(y, x3, train)
        y = Up(f, dw, name="up3")(y, x2, train)
        y = Up(f, dw, name="up4")(y, x1, train)
        return Conv(1, 1, dot_wgrad=dw, name="outc")(y)[..., 0]


# ----------------------------------------------------------------------------- state


@flax.struct.dataclass
class UNetState:
    """U-Net variables and optimizer state (all arrays: a plain pytree)."""

    params: Any
    batch_stats: Any
    opt_state: Any
    step: jax.Array  # int32[], SGD steps taken


def make_optimizer(cfg: SegmentationConfig) -> optax.GradientTransformation:
    """Appendix B.1: Nesterov SGD (lr, momentum) with L2 weight decay added to the gradient.

    Decay goes before SGD so it enters the momentum buffer, as PyTorch's ``SGD(weight_decay=)``.
    """
    return optax.chain(
        optax.add_decayed_weights(cfg.unet_weight_decay),
        optax.sgd(cfg.unet_lr, momentum=cfg.unet_momentum, nesterov=True),
    )


def init_unet(key: jax.Array, features: int, height: int, width: int,
              cfg: SegmentationConfig | None = None) -> UNetState:
    """Fresh U-Net of base width ``features`` for ``height x width`` images.

    ``cfg`` only picks the optimizer (default ``SegmentationConfig()``); the optimizer state's
    structure does not depend on its hyper-parameters.
    """
    if not (isinstance(features, (int, np.integer)) and features > 0):
        raise ValueError(f"unet: features={features!r}: expected a positive int")
    _check_hw(height, width)
    cfg = SegmentationConfig() if cfg is None else cfg
    variables = _init_variables(key, int(features), int(height), int(width))
    params = variables["params"]
    # Jitted too (eager optax init compiles one zeros_like per leaf); tiny, so not cached.
    opt_state = jax.jit(make_optimizer(cfg).init)(params)
    return UNetState(params=params, batch_stats=variables["batch_stats"], opt_state=opt_state,
                     step=jnp.zeros((), jnp.int32))


@functools.partial(jax.jit, static_argnums=(1, 2, 3))
def _init_variables(key, features, height, width):
    # Jitted: an eager linen init dispatches and compiles op by op (~30-50 s on the shared
    # 2-core CPU). Parameters are drawn from an "rbg" key derived from the caller's key: flax
    # derives a threefry key per parameter, and those kernels took 37 s to compile there vs 6 s
    # with rbg's RngBitGenerator. Deterministic per key and backend.
    rbg_key = jax.random.wrap_key_data(jax.random.bits(key, (4,), jnp.uint32), impl="rbg")
    return UNet(features).init(rbg_key, jnp.zeros((1, height, width, 3), jnp.float32))


def _module_for(params) -> UNet:
    # The base width is the 1x1 output conv's input width: no need to store it beside params.
    return UNet(int(params["outc"]["kernel"].shape[2]))


# ----------------------------------------------------------------------------- validation


def _check_hw(h, w):
    if h <= 0 or w <= 0 or h % _DIVISOR or w % _DIVISOR:
        raise ValueError(f"unet: image height and width must be positive multiples of {_DIVISOR} "
                         f"(4 max-pools), got {h}x{w}")


def _desc(x) -> str:
    dtype = getattr(x, "dtype", type(x).__name__)
    return f"{dtype} {list(np.shape(x))}"


def _check_images(images, batched: bool = True):
    """uint8 [N, H, W, 3] (or [H, W, 3] when ``batched`` is False); works on tracers too."""
    expected = "[N, H, W, 3]" if batched else "[H, W, 3] or [N, H, W, 3]"
    ndims = (4,) if batched else (3, 4)
    shape = np.shape(images)
    if getattr(images, "dtype", None) != np.uint8 or len(shape) not in ndims or shape[-1] != 3:
        raise ValueError(f"unet: expected uint8 images {expected}, got {_desc(images)}")
    _check_hw(shape[-3], shape[-2])


def _check_labels(images, labels):
    want = list(np.shape(images)[:3])
    if list(np.shape(labels)) != want:
        raise ValueError(f"unet: expected labels [N, H, W] = {want} matching the images, "
                         f"got {_desc(labels)}")


def _to_float(images_uint8):
    return images_uint8.astype(jnp.float32) / 255.0


# ----------------------------------------------------------------------------- loss / step


def bce_loss(logits: jax.Array, labels: jax.Array, weights: jax.Array | None = None) -> jax.Array:
    """Per-pixel sigmoid BCE, mean over all pixels (optionally times per-pixel ``weights``)."""
    loss = optax.sigmoid_binary_cross_entropy(logits, labels.astype(logits.dtype))
    if weights is not None:
        loss = loss * weights
    return jnp.mean(loss)


def train_step(state: UNetState, images_uint8: jax.Array, labels: jax.Array,
               cfg: SegmentationConfig) -> tuple[UNetState, dict]:
    """One Nesterov-SGD step on a minibatch (BatchNorm in train mode); ``fit_unet``'s scan body.

    images uint8 [B, H, W, 3], labels {0, 1} (bool/int/float) [B, H, W]. Pure; jit with
    ``jax.jit(train_step, static_argnames="cfg")`` (configs are frozen, hence hashable).
    Returns the new state and ``{"loss", "accuracy"}`` (pixel accuracy at p = 0.5).
    """
    _check_images(images_uint8)  # shapes and dtypes only: fine on tracers
    _check_labels(images_uint8, labels)
    model = _module_for(state.params)
    x = _to_float(images_uint8)
    labels = labels.astype(jnp.float32)

    def loss_fn(params):
        logits, updates = model.apply({"params": params, "batch_stats": state.batch_stats}, x,
                                      train=True, mutable=["batch_stats"])
        return bce_loss(logits, labels), (logits, updates["batch_stats"])

    (loss, (logits, batch_stats)), grads = jax.value_and_grad(loss_fn, has_aux=True)(state.params)
    updates, opt_state = make_optimizer(cfg).update(grads, state.opt_state, state.params)
    params = optax.apply_updates(state.params, updates)
    accuracy = jnp.mean((logits > 0) == (labels > 0.5))
    new = state.replace(params=params, batch_stats=batch_stats, opt_state=opt_state,
                        step=state.step + 1)
    return new, {"loss": loss, "accuracy": accuracy}


# ----------------------------------------------------------------------------- fit


@functools.lru_cache(maxsize=8)
def _fit_epoch_fn(cfg: SegmentationConfig, n: int, h: int, w: int,
                  augment_fn: Callable | None):
    """jit of one epoch over n images, built once per (config, shape, augmentation): a second
    fit in the process (e.g. another run of the same task) reuses its compiled program."""
    bs = cfg.unet_batch_size
    n_batches = n // bs

    def epoch(state, key, images, labels):
        TRACE_COUNTS["fit_unet.epoch"] += 1
        perm_key, aug_key = jax.random.split(key)
        # Index batches only; images are gathered per step so no shuffled copy is materialised.
        idx = jax.random.permutation(perm_key, n)[: n_batches * bs].reshape(n_batches, bs)

        def body(state, xs):
            batch_idx, k = xs
            x, y = images[batch_idx], labels[batch_idx]
            if augment_fn is not None:
                x, y = augment_fn(k, x, y)
                if x.dtype != jnp.uint8 or x.shape != (bs, h, w, 3) or y.shape != (bs, h, w):
                    raise ValueError(f"unet: augment_fn must return uint8 images {[bs, h, w, 3]} "
                                     f"and labels {[bs, h, w]}, got {_desc(x)} and {_desc(y)}")
            return train_step(state, x, y, cfg)

        state, metrics = lax.scan(body, state, (idx, jax.random.split(aug_key, n_batches)))
        return state, jnp.mean(metrics["loss"])

    return jax.jit(epoch, donate_argnums=0)


def fit_unet(key: jax.Array, images_uint8, labels, cfg: SegmentationConfig, *,
             augment_fn: Callable | None = None,
             progress: Callable[[int, float], Any] | None = None,
             init_state: UNetState | None = None) -> tuple[UNetState, list[float]]:
    """Train a U-Net for ``cfg.unet_epochs`` epochs of shuffled ``cfg.unet_batch_size`` batches.

    Each epoch is one jitted call scanning over ``N // batch`` minibatches (the remainder is
    dropped and re-drawn by the next shuffle). ``augment_fn(key, images, labels) -> (images,
    labels)`` is a pure, jittable per-minibatch hook (uint8 images in and out, e.g. pasting
    synthetic distractors). ``progress(epoch, mean_loss)`` is called after every epoch.
    ``init_state`` resumes from a given state instead of a fresh ``init_unet``.
    Returns the final state and the per-epoch mean training loss.
    """
    _check_images(images_uint8)
    _check_labels(images_uint8, labels)
    n, h, w, _ = np.shape(images_uint8)
    bs = cfg.unet_batch_size
    if n < bs:
        raise ValueError(f"unet: {n} training images is fewer than unet_batch_size={bs}")

    key, init_key = jax.random.split(key)
    state = init_unet(init_key, cfg.unet_features, h, w, cfg) if init_state is None else init_state
    images = jnp.asarray(images_uint8)
    labels = jnp.asarray(labels)

    epoch_fn = _fit_epoch_fn(cfg, n, h, w, augment_fn)
    history = []
    for e, k in enumerate(jax.random.split(key, cfg.unet_epochs)):
        state, loss = epoch_fn(state, k, images, labels)
        history.append(float(loss))
        if progress is not None:
            progress(e, history[-1])
    return state, history


# ----------------------------------------------------------------------------- inference


@jax.jit
def robot_probability(state_or_params, images_uint8: jax.Array) -> jax.Array:
    """P(robot) per pixel, BatchNorm in eval mode: uint8 [B, H, W, 3] -> float32 [B, H, W].

    Accepts a ``UNetState`` or a variables dict ``{"params", "batch_stats"}``, and a single
    image [H, W, 3] (-> [H, W]). Jitted; composes with outer ``jit`` / ``vmap``.
    """
    if isinstance(state_or_params, UNetState):
        variables = {"params": state_or_params.params,
                     "batch_stats": state_or_params.batch_stats}
    elif isinstance(state_or_params, Mapping) and {"params", "batch_stats"} <= state_or_params.keys():
        variables = {"params": state_or_params["params"],
                     "batch_stats": state_or_params["batch_stats"]}
    else:  # bare params lack the BatchNorm running statistics eval mode needs
        raise ValueError("unet: expected a UNetState or variables {'params', 'batch_stats'}, got "
                         f"{type(state_or_params).__name__}")
    _check_images(images_uint8, batched=False)
    single = images_uint8.ndim == 3
    x = _to_float(images_uint8[None] if single else images_uint8)
    prob = jax.nn.sigmoid(_module_for(variables["params"]).apply(variables, x, train=False))
    return prob[0] if single else prob
