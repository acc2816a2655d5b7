"""jax.numpy port of OpenCV's BackgroundSubtractorMOG2 (CPU path), bit-exact.

Behaviour follows OpenCV's ``bgfg_gaussmix2.cpp`` step by step:
the learning-rate rule (including OpenCV's re-initialisation on ``learningRate >= 1``), the
per-slot weight decay with the prune quirk (a pruned slot keeps its place with weight 0 and the
last slot is dropped unprocessed), bubbling of the matched mode (ties move up), renormalisation
by the float32 reciprocal, new-mode creation / replacement of the weakest mode, the shadow test
on the updated model and ``getBackgroundImage``.

Layout: fixed shapes, ``M = n_mixtures`` slots per pixel plus an active count ``n_modes``,
stored slot-major (``weights[M, H, W]``, ``means[M, C, H, W]``; ``*_hwm`` properties give the
pixel-major view). Every branch of the C++ loop is a ``where`` on whole rows of pixels; the
slot loop is a ``fori_loop`` (unrolled, XLA re-computes earlier slots inside every consumer:
4x slower on CPU) that carries only the weights (the bubble needs this frame's earlier
weights) and sets the matched mode's mean/variance aside; the frame's single reordering (the
matched mode or the new mode bubbling up, never both) is applied once at the end. A batch of
models (``init_batch``) is processed natively as more pixel rows, without ``vmap``. Storing
[H, W, M] as OpenCV does cost about half the step time on CPU in transposes.

Learning rate: ``alphaT``, ``alpha1`` and ``prune`` are traced float32 scalars, so nothing is
recompiled per frame. For the automatic rate (``learning_rate < 0`` or the first frame) the
float64 values ``1 / min(2 n, history)`` and ``-lr * double(ct)`` are rounded to float32 on the
host into a table indexed in-graph by ``min(2 n, history)``; a user rate given as a Python number
is rounded on the host the same way (a traced rate is taken as float32, which is exact whenever
the rate is representable in float32).

FMA: XLA's CPU and GPU backends contract ``a * b + c`` into a fused multiply-add, whose single
rounding flips pixels near knife edges such as ``alphaT = 1 - TB`` (measured here without the
guard: 49 of 504 short test videos not exact, down to 92.5% of a frame). A bitcast
round-trip alone does not help (XLA/LLVM fold it away, as do ``reduce_precision`` to float32
and ``optimization_barrier``; all checked). Instead every product that feeds an add goes
through ``_rounded``: bitcast to int32, XOR with a *runtime* zero, bitcast back. The zero is
``min(n_frames, 0)`` read from the model, which the compiler cannot prove to be 0, so the
product must be materialised in float32 before the add (one integer XOR per product, no global
XLA flag). If a caller builds the model inside the same ``jit`` as its first ``apply``,
``n_frames`` is a constant and the guard could be folded; models come from ``init`` outside.
"""
from __future__ import annotations

import collections
import functools
import numbers
from typing import Any

import flax.struct
import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

# Python-side trace counters: a traced body increments its entry once per compilation.
TRACE_COUNTS: collections.Counter = collections.Counter()

_FLT_EPSILON = np.float32(np.finfo(np.float32).eps)


@flax.struct.dataclass
class MOG2Model:
    """Per-pixel Gaussian mixtures (state) plus OpenCV's parameters (static).

    Storage is slot-major (each slot a contiguous image), the layout the update vectorises
    over; ``weights_hwm`` / ``variances_hwm`` / ``means_hwmc`` give OpenCV's pixel-major view.
    A batch of models has one more leading axis on every array (see ``init_batch``).
    """

    weights: jax.Array  # float32[M, H, W]
    variances: jax.Array  # float32[M, H, W]
    means: jax.Array  # float32[M, C, H, W]
    n_modes: jax.Array  # int32[H, W], slots in use
    n_frames: jax.Array  # int32[], frames seen since (re)initialisation
    history: int = flax.struct.field(pytree_node=False, default=500)
    var_threshold: float = flax.struct.field(pytree_node=False, default=16.0)
    background_ratio: float = flax.struct.field(pytree_node=False, default=0.9)
    var_threshold_gen: float = flax.struct.field(pytree_node=False, default=9.0)
    var_init: float = flax.struct.field(pytree_node=False, default=15.0)
    var_min: float = flax.struct.field(pytree_node=False, default=4.0)
    var_max: float = flax.struct.field(pytree_node=False, default=75.0)
    ct: float = flax.struct.field(pytree_node=False, default=0.05)
    shadow_value: int = flax.struct.field(pytree_node=False, default=127)
    shadow_threshold: float = flax.struct.field(pytree_node=False, default=0.5)
    detect_shadows: bool = flax.struct.field(pytree_node=False, default=True)
    n_mixtures: int = flax.struct.field(pytree_node=False, default=5)

    @property
    def image_shape(self) -> tuple[int, int, int]:
        """(H, W, C) of the frames this model takes (ignores leading batch axes)."""
        return tuple(self.n_modes.shape[-2:]) + (self.means.shape[-3],)

    @property
    def batch_shape(self) -> tuple[int, ...]:
        """Leading batch axes: () for one model, (B,) for ``init_batch(B, ...)``."""
        return tuple(self.n_frames.shape)

    @property
    def weights_hwm(self) -> jax.Array:
        """weights as float32[..., H, W, M]."""
        return jnp.moveaxis(self.weights, -3, -1)

    @property
    def variances_hwm(self) -> jax.Array:
        """variances as float32[..., H, W, M]."""
        return jnp.moveaxis(self.variances, -3, -1)

    @property
    def means_hwmc(self) -> jax.Array:
        """means as float32[..., H, W, M, C]."""
        return jnp.moveaxis(self.means, (-4, -3), (-2, -1))


def init(h: int, w: int, c: int, history: int = 500, var_threshold: float = 16.0,
         detect_shadows: bool = True, n_mixtures: int = 5, background_ratio: float = 0.9,
         var_threshold_gen: float = 9.0, var_init: float = 15.0, var_min: float = 4.0,
         var_max: float = 75.0, ct: float = 0.05, shadow_value: int = 127,
         shadow_threshold: float = 0.5) -> MOG2Model:
    """Empty model, like ``cv2.createBackgroundSubtractorMOG2`` + its setters (snake_case)."""
    for name, v in (("h", h), ("w", w)):
        if not isinstance(v, numbers.Integral) or v < 1:
            raise ValueError(f"{name}={v!r}: expected a positive int")
    if c not in (1, 3):
        raise ValueError(f"c={c!r}: expected 1 or 3 channels")
    if not isinstance(n_mixtures, numbers.Integral) or not 1 <= n_mixtures <= 255:
        raise ValueError(f"n_mixtures={n_mixtures!r}: expected an int in 1..255")
    if not isinstance(shadow_value, numbers.Integral) or not 0 <= shadow_value <= 255:
        raise ValueError(f"shadow_value={shadow_value!r}: expected an int in 0..255")
    # OpenCV's constructor falls back to its defaults for non-positive values.
    history = int(history) if history > 0 else 500
    var_threshold = float(np.float32(var_threshold)) if var_threshold > 0 else 16.0
    f32 = lambda v: float(np.float32(v))
    m = int(n_mixtures)
    return MOG2Model(
        weights=jnp.zeros((m, h, w), jnp.float32),
        variances=jnp.zeros((m, h, w), jnp.float32),
        means=jnp.zeros((m, c, h, w), jnp.float32),
        n_modes=jnp.zeros((h, w), jnp.int32),
        n_frames=jnp.zeros((), jnp.int32),
        history=history, var_threshold=var_threshold,
        background_ratio=f32(background_ratio), var_threshold_gen=f32(var_threshold_gen),
        var_init=f32(var_init), var_min=f32(var_min), var_max=f32(var_max), ct=f32(ct),
        shadow_value=int(shadow_value), shadow_threshold=f32(shadow_threshold),
        detect_shadows=bool(detect_shadows), n_mixtures=m)


# ----------------------------------------------------------------------------- learning rate

@functools.lru_cache(maxsize=32)
def _auto_rate_tables(history: int, ct: float) -> tuple[np.ndarray, np.ndarray]:
    """alphaT and prune for ``lr = 1 / m`` (m = min(2 n, history)), rounded like OpenCV."""
    m = np.arange(history + 1, dtype=np.float64)
    m[0] = 1.0  # unused entry
    lr = 1.0 / m
    return lr.astype(np.float32), (-lr * np.float64(np.float32(ct))).astype(np.float32)


def _user_rate(learning_rate: Any, ct: float, shape: tuple[int, ...] = ()) -> dict:
    """Per-call rate inputs (traced): float32 alphaT/prune of a user rate plus two flags."""
    if isinstance(learning_rate, jax.Array) and not isinstance(learning_rate, np.ndarray):
        lr = jnp.broadcast_to(jnp.asarray(learning_rate, jnp.float32), shape)
        return {"alpha": lr, "prune": -lr * np.float32(ct), "nonneg": lr >= 0, "reset": lr >= 1}
    lr = np.asarray(learning_rate, dtype=np.float64)
    if lr.ndim and lr.shape != shape[-lr.ndim:]:
        raise ValueError(f"learning_rate with shape {lr.shape}: expected a scalar or {shape}")
    lr = np.broadcast_to(lr, shape)
    return {"alpha": jnp.asarray(lr.astype(np.float32)),
                "prune": jnp.asarray((-lr * np.float64(np.float32(ct))).astype(np.float32)),
                "nonneg": jnp.asarray(lr >= 0), "reset": jnp.asarray(lr >= 1)}


# ----------------------------------------------------------------------------- the update

def _rounded(p: jax.Array, zero: jax.Array) -> jax.Array:
    """``p`` rounded to float32 before any add: an opaque int round-trip blocks FMA fusion."""
    bits = lax.bitcast_convert_type(p, jnp.int32) ^ zero
    return lax.bitcast_convert_type(bits, jnp.float32)


def _dot(a: list, b: list, zero: jax.Array) -> jax.Array:
    """Channel-order ``sum a_c * b_c`` with float32 rounding after each product."""
    s = _rounded(a[0] * b[0], zero)
    for ac, bc in zip(a[1:], b[1:]):
        s = s + _rounded(ac * bc, zero)
    return s


def _reciprocal(total: jax.Array) -> jax.Array:
    """OpenCV's renormalising factor: 1 / total, or 0 where |total| <= FLT_EPSILON."""
    return jnp.where(jnp.abs(total) > _FLT_EPSILON, np.float32(1) / total, np.float32(0))


def _slot_match(model: MOG2Model, x: list, mu_k: list, var_k: jax.Array, check: jax.Array,
                weight_before: jax.Array, zero: jax.Array):
    """One slot's test of the pixels still to match (`check`): (squared distance, background
    (within var_threshold while the slots before it weigh under background_ratio), fit (within
    var_threshold_gen)). x, mu_k: lists over channels."""
    d = [m - xc for m, xc in zip(mu_k, x)]
    dist2 = _dot(d, d, zero)
    background = check & (weight_before < np.float32(model.background_ratio)) & (
        dist2 < np.float32(model.var_threshold) * var_k)
    return d, dist2, background, check & (dist2 < np.float32(model.var_threshold_gen) * var_k)


def _mask(model: MOG2Model, background: jax.Array, x: list, w: list, var: list, mu: list,
          nm: jax.Array, zero: jax.Array) -> jax.Array:
    """uint8 mask of pixel rows: 0 background, else shadow_value for a shadow (tested on the
    model w, var, mu: lists over slots), else 255."""
    if model.detect_shadows:
        shadow = _shadow(model, x, w, var, mu, nm, zero)
        fg = jnp.where(shadow, np.uint8(model.shadow_value), np.uint8(255))
    else:
        fg = jnp.full(background.shape, 255, jnp.uint8)
    return jnp.where(background, np.uint8(0), fg)


def _shadow(model: MOG2Model, x: list, w: list, var: list, mu: list, nm: jax.Array,
            zero: jax.Array) -> jax.Array:
    """OpenCV's detectShadowGMM on every pixel (x, mu: lists over channels of [H, W])."""
    tb, big_tb = np.float32(model.var_threshold), np.float32(model.background_ratio)
    tau = np.float32(model.shadow_threshold)
    done = jnp.zeros(nm.shape, bool)
    shadow = jnp.zeros(nm.shape, bool)
    t_w = jnp.zeros(nm.shape, jnp.float32)
    for t in range(model.n_mixtures):
        act = (t < nm) & ~done
        num = _dot(x, mu[t], zero)
        den = _dot(mu[t], mu[t], zero)
        act_z = act & (den == 0)  # "no division by zero": the whole test answers no
        act = act & ~act_z
        a = num / den
        dd = [_rounded(a * m_c, zero) - x_c for m_c, x_c in zip(mu[t], x)]
        d2a = _dot(dd, dd, zero)
        hit = act & (num <= den) & (num >= tau * den) & (d2a < ((tb * var[t]) * a) * a)
        t_w = jnp.where(act & ~hit, t_w + w[t], t_w)
        done = done | act_z | hit | (act & (t_w > big_tb))
        shadow = shadow | hit
    return shadow


def _apply_impl(model: MOG2Model, frame: jax.Array, rate: dict) -> tuple[MOG2Model, jax.Array]:
    """One frame per model: OpenCV's MOG2Invoker on every pixel at once.

    Works natively on a batch of models (leading axes of every model array, of the frames and
    of the rate inputs); pixels of all models are processed together as rows ``[*lead, P]``.
    """
    TRACE_COUNTS["apply_step"] += 1
    m_slots, n_ch = model.n_mixtures, model.means.shape[-3]
    h, w_img = model.n_modes.shape[-2:]
    lead = model.n_frames.shape
    px = lead + (h * w_img,)  # row shape: pixels last, contiguous
    var_min = np.float32(min(model.var_min, model.var_max))
    var_max = np.float32(max(model.var_min, model.var_max))

    # Learning rate (OpenCV's apply()): re-initialise on the first frame or lr >= 1.
    reset = (model.n_frames == 0) | rate["reset"]
    n = jnp.where(reset, 0, model.n_frames) + 1
    hist = model.history
    k_tab = jnp.minimum(2 * jnp.minimum(n, hist), hist)
    tab_alpha, tab_prune = _auto_rate_tables(hist, model.ct)
    use_user = rate["nonneg"] & (n > 1)
    alpha_t = jnp.where(use_user, rate["alpha"], jnp.asarray(tab_alpha)[k_tab])
    prune = jnp.where(use_user, rate["prune"], jnp.asarray(tab_prune)[k_tab])
    alpha1 = np.float32(1) - alpha_t
    zero = jnp.minimum(model.n_frames, 0)  # runtime 0 for the anti-FMA guard
    # Per-model scalars broadcast against rows [*lead, P].
    alpha_t, prune, alpha1, zero = (a[..., None] for a in (alpha_t, prune, alpha1, zero))
    rnd = functools.partial(_rounded, zero=zero)

    # Working layout = storage layout with pixels flattened: slot rows [*lead, M, P] are
    # contiguous and vectorise; only the (uint8) frame is transposed to [*lead, C, P].
    nl = len(lead)
    sa = nl  # slot axis
    x = jnp.moveaxis(frame.reshape(px + (n_ch,)), -1, nl).astype(jnp.float32)
    x = [lax.index_in_dim(x, c, nl, keepdims=False) for c in range(n_ch)]
    w0 = model.weights.reshape(lead + (m_slots,) + px[-1:])
    var0 = model.variances.reshape(lead + (m_slots,) + px[-1:])
    mu0 = model.means.reshape(lead + (m_slots, n_ch) + px[-1:])
    nm0 = jnp.where(reset[..., None], 0, model.n_modes.reshape(px))
    slots = jnp.arange(m_slots, dtype=jnp.int32)[:, None]  # broadcasts against [*lead, M, P]
    zeros_b = jnp.zeros(px, bool)
    zeros_i = jnp.zeros(px, jnp.int32)

    def at(a, k):  # slot k (static or traced) of a [*lead, M, ...] array
        return lax.dynamic_index_in_dim(a, k, sa, keepdims=False) if isinstance(k, jax.Array) \
            else lax.index_in_dim(a, k, sa, keepdims=False)

    def chan(a, c):  # channel c of a [*lead, C, P] array
        return lax.index_in_dim(a, c, nl, keepdims=False)

    def expand(a):  # [*lead, P] -> [*lead, 1, P], to broadcast against slot arrays
        return jnp.expand_dims(a, sa)

    # 1. Decay / match / prune, in slot order; nm shrinks inside the loop on pruning. A loop
    #    rather than unrolled code: XLA would otherwise re-compute the chain of earlier slots
    #    inside every consumer.
    def body(k, carry):
        w, nm, fitted, background, total_w, src, dst, fit_var, fit_mu = carry
        wk, vk, muk = at(w, k), at(var0, k), at(mu0, k)
        muk = [chan(muk, c) for c in range(n_ch)]
        active = k < nm
        weight = rnd(alpha1 * wk) + prune
        d, dist2, bg_k, fit = _slot_match(model, x, muk, vk, active & ~fitted, total_w, zero)
        background = background | bg_k
        weight = jnp.where(fit, weight + alpha_t, weight)
        kk = alpha_t / weight
        # Only the matched slot's mean and variance change: keep them aside, write after.
        fit_mu = [jnp.where(fit, muk[c] - rnd(kk * d[c]), fit_mu[c]) for c in range(n_ch)]
        var_k = jnp.minimum(jnp.maximum(vk + rnd(kk * (dist2 - vk)), var_min), var_max)
        fit_var = jnp.where(fit, var_k, fit_var)
        # Bubble up while weight >= w[i-1]: stop below the last earlier slot that is larger
        # (earlier slots already hold this frame's weights).
        pos = zeros_i
        for j in range(m_slots - 1):
            pos = jnp.where((j < k) & (at(w, j) > weight), j + 1, pos)
        src = jnp.where(fit, k, src)
        dst = jnp.where(fit, pos, dst)
        fitted = fitted | fit
        pruned = active & (weight < -prune)  # the prune quirk: slot stays, with weight 0
        weight = jnp.where(pruned, np.float32(0), weight)
        nm = nm - pruned.astype(jnp.int32)
        w = lax.dynamic_update_index_in_dim(w, jnp.where(active, weight, wk), k, sa)
        total_w = jnp.where(active, total_w + weight, total_w)
        return w, nm, fitted, background, total_w, src, dst, fit_var, fit_mu

    zeros_f = jnp.zeros(px, jnp.float32)
    carry = (w0, nm0, zeros_b, zeros_b, zeros_f, zeros_i, zeros_i, zeros_f, [zeros_f] * n_ch)
    w, nm, fitted, background, total_w, src, dst, fit_var, fit_mu = lax.fori_loop(
        0, m_slots, body, carry)
    upd = expand(fitted) & (slots == expand(src))
    var = jnp.where(upd, expand(fit_var), var0)
    mu = jnp.where(jnp.expand_dims(upd, nl + 1), expand(jnp.stack(fit_mu, nl)), mu0)

    # 2. Renormalise the slots still in use by the float32 reciprocal (multiply, not divide).
    inv = _reciprocal(total_w)
    w = jnp.where(slots < expand(nm), w * expand(inv), w)

    # 3. No match: a new mode in slot nm, or replace the weakest (slot M-1) when full.
    create = ~fitted & (alpha_t > 0)
    slot = jnp.where(nm == m_slots, m_slots - 1, nm)
    nm = jnp.where(create, jnp.minimum(nm + 1, m_slots), nm)
    only = nm == 1
    here = expand(create) & (slots == expand(slot))
    below = expand(create & ~only) & (slots < expand(slot))
    w = jnp.where(here, jnp.where(expand(only), np.float32(1), expand(alpha_t)),
                  jnp.where(below, w * expand(alpha1), w))
    var = jnp.where(here, np.float32(model.var_init), var)
    mu = jnp.where(jnp.expand_dims(here, nl + 1), jnp.expand_dims(jnp.stack(x, nl), sa), mu)
    pos = zeros_i
    for j in range(m_slots - 1):
        pos = jnp.where((j < slot) & (at(w, j) > alpha_t), j + 1, pos)
    src = jnp.where(create, slot, src)
    dst = jnp.where(create, pos, dst)

    # 4. The frame's one bubble: slot src moves to dst, slots dst..src-1 move down one.
    src, dst = expand(src), expand(dst)
    from_idx = jnp.where(slots == dst, src,
                         jnp.where((slots > dst) & (slots <= src), slots - 1, slots))
    w_p, var_p, mu_p = w, var, mu
    for i in range(m_slots):
        take = from_idx == i
        w_p = jnp.where(take, expand(at(w, i)), w_p)
        var_p = jnp.where(take, expand(at(var, i)), var_p)
        mu_p = jnp.where(jnp.expand_dims(take, nl + 1), expand(at(mu, i)), mu_p)

    # 5. Mask: background, else shadow (tested on the updated model), else foreground.
    mask = _mask(model, background, x, [at(w_p, t) for t in range(m_slots)],
                 [at(var_p, t) for t in range(m_slots)],
                 [[chan(at(mu_p, t), c) for c in range(n_ch)] for t in range(m_slots)],
                 nm, zero).reshape(lead + (h, w_img))

    new = model.replace(
        weights=w_p.reshape(model.weights.shape), variances=var_p.reshape(model.weights.shape),
        means=mu_p.reshape(model.means.shape), n_modes=nm.reshape(model.n_modes.shape),
        n_frames=n)
    return new, mask


_apply_jit = jax.jit(_apply_impl)
_apply_batch_jit = _apply_jit  # natively batched (leading axes): no vmap


@jax.jit
def _apply_video_jit(model: MOG2Model, frames: jax.Array, rates: dict):
    TRACE_COUNTS["apply_video"] += 1
    return lax.scan(lambda m, xs: _apply_impl(m, *xs), model, (frames, rates))


# ----------------------------------------------------------------------------- input checks

def _check_model(model: Any) -> None:
    if not isinstance(model, MOG2Model):
        raise ValueError(f"model of type {type(model).__name__}: expected a MOG2Model")


def _check_frames(model: MOG2Model, frames: Any, lead: tuple[int, ...], what: str) -> jax.Array:
    """Validate static shape/dtype; returns frames as [*lead, H, W, C] (2-D accepted if C=1)."""
    h, w, c = model.image_shape
    dtype = getattr(frames, "dtype", None)
    shape = tuple(getattr(frames, "shape", ()))
    if dtype is None:
        raise ValueError(f"{what} of type {type(frames).__name__}: expected a uint8 array")
    if dtype != np.uint8:
        raise ValueError(f"{what} with dtype {dtype}: expected uint8")
    nl = len(lead)
    if c == 1 and len(shape) == nl + 2:
        shape = shape + (1,)
        frames = frames[..., None]
    if len(shape) != nl + 3 or shape[nl:nl + 2] != (h, w):
        exp = lead + (h, w, c)
        raise ValueError(f"{what} with shape {tuple(getattr(frames, 'shape', ()))}: "
                         f"expected {exp} ([{'batch, ' if nl else ''}H, W, C])")
    if shape[nl + 2] != c:
        raise ValueError(f"{what} with {shape[nl + 2]} channels (shape {shape}): the model "
                         f"was initialised for {c} channels")
    if lead and shape[:nl] != lead:
        raise ValueError(f"{what} with leading shape {shape[:nl]}: expected {lead}")
    return jnp.asarray(frames)


# ----------------------------------------------------------------------------- public API

def apply(model: MOG2Model, frame: Any, learning_rate: Any = -1.0):
    """One frame: ``(model, mask)``, like ``subtractor.apply(frame, learningRate=lr)``.

    frame: uint8[H, W, C]; mask: uint8[H, W] with 0 (background), ``shadow_value``, 255.
    """
    _check_model(model)
    if model.batch_shape:
        raise ValueError(f"model with batch shape {model.batch_shape}: expected an "
                         "unbatched model (use apply_batch for a batch)")
    frame = _check_frames(model, frame, (), "frame")
    return _apply_jit(model, frame, _user_rate(learning_rate, model.ct))


def apply_batch(model: MOG2Model, frames: Any, learning_rate: Any = -1.0):
    """B independent models (leading axis on every model array) on frames uint8[B, H, W, C].

    learning_rate: a scalar, or one per model (shape [B]).
    """
    _check_model(model)
    if len(model.batch_shape) != 1:
        raise ValueError(f"model with batch shape {model.batch_shape}: expected a batched "
                         "model with one leading axis (init_batch)")
    b = model.batch_shape[0]
    frames = _check_frames(model, frames, (b,), "frames")
    return _apply_batch_jit(model, frames, _user_rate(learning_rate, model.ct, (b,)))


def apply_video(model: MOG2Model, frames: Any, learning_rate: Any = -1.0):
    """Frames uint8[T, H, W, C] in order (one ``lax.scan``): ``(model, masks uint8[T, H, W])``.

    learning_rate: a scalar, or one per frame (shape [T]).
    """
    _check_model(model)
    if model.batch_shape:
        raise ValueError(f"model with batch shape {model.batch_shape}: expected an "
                         "unbatched model")
    lead = tuple(getattr(frames, "shape", ()))[:1]
    if len(lead) != 1 or getattr(frames, "ndim", 0) < 3:
        raise ValueError(f"frames with shape {tuple(getattr(frames, 'shape', ()))}: expected "
                         f"{('T',) + model.image_shape} [T, H, W, C]")
    frames = _check_frames(model, frames, lead, "frames")
    return _apply_video_jit(model, frames, _user_rate(learning_rate, model.ct, lead))


def init_batch(b: int, h: int, w: int, c: int, **kwargs) -> MOG2Model:
    """``b`` empty models stacked on a leading axis (for ``apply_batch``)."""
    one = init(h, w, c, **kwargs)
    return jax.tree.map(lambda a: jnp.broadcast_to(a, (b,) + a.shape), one)


@jax.jit
def _background_jit(model: MOG2Model) -> jax.Array:
    TRACE_COUNTS["background"] += 1
    zero = jnp.minimum(model.n_frames, 0)
    big_tb = np.float32(model.background_ratio)
    n_ch = model.means.shape[-3]
    shape = model.n_modes.shape
    acc = [jnp.zeros(shape, jnp.float32) for _ in range(n_ch)]
    total = jnp.zeros(shape, jnp.float32)
    done = jnp.zeros(shape, bool)
    for k in range(model.n_mixtures):
        act = (k < model.n_modes) & ~done
        wk = model.weights[..., k, :, :]
        acc = [jnp.where(act, a + _rounded(wk * model.means[..., k, c, :, :], zero), a)
               for c, a in enumerate(acc)]
        total = jnp.where(act, total + wk, total)
        done = done | (act & (total > big_tb))  # the crossing slot is included
    inv = _reciprocal(total)
    # saturate_cast<uchar>(float): round half to even, then clamp.
    img = [jnp.clip(jnp.round(a * inv), 0, 255).astype(jnp.uint8) for a in acc]
    return jnp.stack(img, -1)


def background_image(model: MOG2Model) -> jax.Array:
    """``getBackgroundImage``: uint8[H, W, C] (or [B, H, W, C] for a batched model)."""
    _check_model(model)
    if model.batch_shape:
        return jax.vmap(_background_jit)(model)
    return _background_jit(model)


def _frozen_is_plain(model: MOG2Model) -> jax.Array:
    """Whether a step at lr = 0 leaves this (unbatched) model exactly as it is, so that
    `_frozen_masks` gives `_apply_impl`'s masks: it has seen a frame (no re-initialisation),
    and in every pixel its active slots have positive weights (no 0 / 0 in the update, no
    pruning), variances inside [var_min, var_max] (the update's clamp is a no-op) and strictly
    decreasing weights (a matched mode never bubbles past a tie). Fitted backgrounds are so
    (checked on the five scenes' cpu-preset models); anything else takes the full step."""
    w, var = model.weights, model.variances
    active = jnp.arange(model.n_mixtures)[:, None, None] < model.n_modes
    var_lo, var_hi = min(model.var_min, model.var_max), max(model.var_min, model.var_max)
    ordered = jnp.concatenate([jnp.ones_like(w[:1], bool), w[:-1] > w[1:]], 0)
    ok = (w > 0) & (var >= np.float32(var_lo)) & (var <= np.float32(var_hi)) & ordered
    return (model.n_frames > 0) & jnp.all(ok | ~active)


def _frozen_masks(model: MOG2Model, frames: jax.Array) -> jax.Array:
    """`_apply_impl`'s masks at lr = 0 for a model where `_frozen_is_plain` holds, frames
    uint8[N, H, W, C] -> uint8[N, H, W]: the same float32 operations in the same order, less
    the parts of the step that are identities there (weight decay by 1, zero-size mean and
    variance updates, pruning, mode creation, the bubble), so the per-model sums are taken
    once rather than per frame."""
    m_slots, n_ch = model.n_mixtures, model.means.shape[-3]
    h, w_img = model.n_modes.shape
    n = frames.shape[0]
    zero = jnp.minimum(model.n_frames, 0)
    w = model.weights.reshape(m_slots, -1)
    var = model.variances.reshape(m_slots, -1)
    mu = model.means.reshape(m_slots, n_ch, -1)
    nm = model.n_modes.reshape(-1)
    active = [k < nm for k in range(m_slots)]
    # The step's running total of the decayed weights before each slot (decay by 1 is exact).
    before, total = [], jnp.zeros_like(w[0])
    for k in range(m_slots):
        before.append(total)
        total = jnp.where(active[k], total + w[k], total)
    w_n = jnp.where(jnp.arange(m_slots)[:, None] < nm, w * _reciprocal(total), w)

    x = jnp.moveaxis(frames.reshape(n, h * w_img, n_ch), -1, 0).astype(jnp.float32)
    x = [x[c] for c in range(n_ch)]  # [N, P] each
    fitted = jnp.zeros((n, h * w_img), bool)
    background = fitted
    mu = [[mu[k, c] for c in range(n_ch)] for k in range(m_slots)]
    for k in range(m_slots):
        _, _, bg_k, fit = _slot_match(model, x, mu[k], var[k], active[k] & ~fitted, before[k],
                                      zero)
        background, fitted = background | bg_k, fitted | fit
    return _mask(model, background, x, list(w_n), list(var), mu, nm, zero).reshape(n, h, w_img)


@functools.partial(jax.jit, static_argnames="shadows_as_foreground")
def _foreground_jit(model: MOG2Model, frames: jax.Array, shadows_as_foreground: bool):
    TRACE_COUNTS["foreground"] += 1
    # The next-frame step at lr = 0 (alphaT = 0, prune = -0.0), each frame from the same model.
    rate = {"alpha": jnp.float32(0), "prune": jnp.float32(-0.0), "nonneg": jnp.bool_(True),
                "reset": jnp.bool_(False)}
    batch = min(frames.shape[0], 256)  # chunks of frames: bounded memory for long videos

    def full_step(fr):
        return lax.map(lambda f: _apply_impl(model, f, rate)[1], fr, batch_size=batch)

    if model.batch_shape:
        masks = full_step(frames)
    else:
        masks = lax.cond(_frozen_is_plain(model),
                         lambda fr: lax.map(lambda f: _frozen_masks(model, f[None])[0], fr,
                                            batch_size=batch),
                         full_step, frames)
    if shadows_as_foreground:
        return masks != 0
    return masks == 255


def frozen_foreground(model: MOG2Model, frames: jax.Array,
                      shadows_as_foreground: bool = True) -> jax.Array:
    """`foreground` without input checks, for use inside a caller's jit: frames uint8[N, H, W, C]
    -> bool[N, H, W]."""
    return _foreground_jit(model, frames, shadows_as_foreground)


def foreground(model: MOG2Model, frames: Any, shadows_as_foreground: bool = True) -> jax.Array:
    """Test-time foreground of frames uint8[..., H, W, C] against a frozen model (lr = 0).

    Frame i gets exactly the mask that ``apply(model, frames[i], 0.0)`` would give (frames
    are processed side by side, in chunks of 256; no state is carried between them). For a
    fitted model, whose lr-0 step changes nothing (``_frozen_is_plain``), only the mask's
    part of the step runs (one chunk's 510 frames: 166 -> 29 ms on a 2-core CPU). OpenCV at
    ``learningRate=0`` still renormalises the weights and reorders tied modes from frame to
    frame; that drift is not carried here (use ``apply_video`` with lr 0 for the sequential
    behaviour). Returns bool[..., H, W];
    ``shadows_as_foreground=False`` drops shadow pixels (mask ``shadow_value``).
    """
    _check_model(model)
    if model.batch_shape:
        raise ValueError(f"model with batch shape {model.batch_shape}: expected an "
                         "unbatched model")
    h, w, c = model.image_shape
    ndim = getattr(frames, "ndim", 0)
    extra = 2 if (c == 1 and ndim >= 2 and tuple(frames.shape[-2:]) == (h, w)) else 3
    lead = tuple(frames.shape[:ndim - extra]) if ndim >= extra else ()
    frames = _check_frames(model, frames, lead, "frames")
    flat = frames.reshape((-1, h, w, c))
    out = _foreground_jit(model, flat, shadows_as_foreground=bool(shadows_as_foreground))
    return out.reshape(lead + (h, w))
