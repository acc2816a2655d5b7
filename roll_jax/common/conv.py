"""Convolutions as patch extraction + one matmul, for XLA:CPU.

XLA:CPU runs ``lax.conv_general_dilated`` far below its matmul rate for the encoders' small,
strided shapes, and its kernel-gradient convolution is slower still inside a ``lax.scan``
(where every training loop here runs it). A convolution is a matmul over image patches: the
patches are ``k*k`` strided slices concatenated on the channel axis, so the forward pass is one
``dot`` and the backward two ``dot``s plus pads of the slices -- all ops XLA:CPU runs near its
matmul rate. The kernel gradient is computed as ``g^T P`` with the transposed output gradient
``g^T`` materialised (`weight_gradient`): left to itself, XLA:CPU contracts ``P`` and ``g``
over their major axis, a form its YNNPACK dots do not take (that form adds 14-17% to the
object-VAE train step, 27-50% to the U-Net's). Measured figures: bench/roofline.py,
docs/encoders.md ("Speed on the CPU").

``Conv`` / ``ConvTranspose`` are drop-in replacements for flax's ``nn.Conv`` /
``nn.ConvTranspose`` with ``padding="VALID"``: the same parameter names, shapes
(kernel [k, k, in, out], bias [out]) and initialisers, the same values within float32
roundoff (tests/test_conv.py compares values and gradients), so checkpoints are unchanged.
"""
from __future__ import annotations

import flax.linen as nn
import jax
import jax.numpy as jnp


def transposed_rows(x: jnp.ndarray) -> jnp.ndarray:
    """[..., N] -> [N, M] (M = the product of the leading axes), materialised: the optimisation
    barrier keeps XLA from folding the transpose back into the dot that consumes it."""
    return jax.lax.optimization_barrier(x.reshape(-1, x.shape[-1]).T)


def weight_gradient(g_t: jnp.ndarray, p: jnp.ndarray) -> jnp.ndarray:
    """sum over rows of p [..., K] outer g -> [K, N], from g_t = `transposed_rows(g)` [N, M]: one
    canonical [N, M] x [M, K] dot (the barrier keeps XLA from turning it into the P^T g form),
    then a transpose of the small result."""
    return jax.lax.optimization_barrier(g_t @ p.reshape(-1, p.shape[-1])).T


@jax.custom_vjp
def patch_matmul(p: jnp.ndarray, w: jnp.ndarray) -> jnp.ndarray:
    """p [..., K] @ w [K, N], its kernel gradient by `weight_gradient` (same values as
    autodiff's)."""
    return p @ w


def _patch_matmul_fwd(p, w):
    return p @ w, (p, w)


def _patch_matmul_bwd(res, g):
    p, w = res
    return g @ w.T, weight_gradient(transposed_rows(g), p)


patch_matmul.defvjp(_patch_matmul_fwd, _patch_matmul_bwd)


def patches(x: jnp.ndarray, k: int, stride: int) -> jnp.ndarray:
    """[B, H, W, C] -> [B, Ho, Wo, k*k*C], the VALID ``k x k`` windows at ``stride``, in the
    kernel's (row, column, channel) order."""
    _, h, w, _ = x.shape
    ho, wo = (h - k) // stride + 1, (w - k) // stride + 1
    cols = [x[:, i:i + stride * (ho - 1) + 1:stride, j:j + stride * (wo - 1) + 1:stride]
            for i in range(k) for j in range(k)]
    return jnp.concatenate(cols, axis=-1)


def conv_valid(x: jnp.ndarray, kernel: jnp.ndarray, stride: int) -> jnp.ndarray:
    """VALID cross-correlation, ``nn.Conv(padding="VALID")``'s: x [B, H, W, Cin], kernel
    [k, k, Cin, Cout] -> [B, Ho, Wo, Cout]."""
    k, _, cin, cout = kernel.shape
    if x.shape[-1] != cin:
        raise ValueError(f"input has {x.shape[-1]} channels, the kernel expects {cin}")
    return patch_matmul(patches(x, k, stride), kernel.reshape(k * k * cin, cout))


def conv_transpose_valid(x: jnp.ndarray, kernel: jnp.ndarray, stride: int) -> jnp.ndarray:
    """``nn.ConvTranspose(padding="VALID")``: x [B, H, W, Cin], kernel [k, k, Cin, Cout] ->
    [B, (H-1)*s + max(k, s), (W-1)*s + max(k, s), Cout] (lax's VALID transpose size).

    Output pixel ``p = i*s + r`` receives ``x[i] @ kernel[k-1-r]`` (flax does not transpose the
    kernel, so it acts flipped). With the flipped kernel zero-padded to ``m*s`` taps, output
    block ``b`` (its ``s x s`` pixels) is ``sum_a x[b-a] @ W_a`` over ``a < m``: a stride-1
    ``m x m`` convolution of the input padded by ``m-1``, with ``s*s*Cout`` output channels,
    then depth-to-space and a crop.
    """
    k, _, cin, cout = kernel.shape
    if x.shape[-1] != cin:
        raise ValueError(f"input has {x.shape[-1]} channels, the kernel expects {cin}")
    s = stride
    m = -(-k // s)
    wf = jnp.flip(kernel, (0, 1))
    wf = jnp.pad(wf, ((0, m * s - k), (0, m * s - k), (0, 0), (0, 0)))
    # [a*s + r, a'*s + r', ci, co] -> [a, a', ci, r, r', co], tap a applied at block b from x[b-a]
    wb = wf.reshape(m, s, m, s, cin, cout).transpose(0, 2, 4, 1, 3, 5)
    # the stride-1 conv over the padded input reads x[b - a] as window offset m-1-a
    wb = jnp.flip(wb, (0, 1)).reshape(m * m * cin, s * s * cout)
    b, h, w, _ = x.shape
    xp = jnp.pad(x, ((0, 0), (m - 1, m - 1), (m - 1, m - 1), (0, 0)))
    y = patch_matmul(patches(xp, m, 1), wb)  # [B, H+m-1, W+m-1, s*s*Cout]
    return _blocks_to_image(y.reshape(b, h + m - 1, w + m - 1, s, s, cout), h, w, k, s)


def _blocks_to_image(y: jnp.ndarray, h: int, w: int, k: int, s: int) -> jnp.ndarray:
    """Output blocks [B, Hb, Wb, s, s, Cout] of a transposed conv of an H x W input ->
    depth-to-space, cropped to lax's VALID size (H-1)*s + max(k, s)."""
    b, hb, wb, _, _, cout = y.shape
    y = y.transpose(0, 1, 3, 2, 4, 5).reshape(b, hb * s, wb * s, cout)
    size = max(k, s)
    return y[:, :(h - 1) * s + size, :(w - 1) * s + size]


def conv_transpose_col2im(x: jnp.ndarray, kernel: jnp.ndarray, stride: int) -> jnp.ndarray:
    """`conv_transpose_valid` as one matmul without wasted taps, then an overlap-add.

    ``x [B*H*W, Cin] @ kernel [Cin, k*k*Cout]`` gives every tap's contribution; tap
    ``a = q*s + r`` lands in output phase ``r`` at block ``i + q``, so each phase image is a
    sum of block-shifted (plainly padded) tap images, and depth-to-space interleaves the
    phases. The patch form computes ``(H+m-1)^2 m^2 s^2 / (H^2 k^2)`` times the useful
    multiply-adds (3.2x for the VAE's 3x3 -> 7x7 layer), this one none, at the cost of
    ``k*k`` adds on the block grid: faster where the input is small against the kernel,
    slower elsewhere (measured per layer; only the decoder's 3x3 -> 7x7 layer takes it:
    docs/encoders.md, "Speed on the CPU").
    """
    k, _, cin, cout = kernel.shape
    if x.shape[-1] != cin:
        raise ValueError(f"input has {x.shape[-1]} channels, the kernel expects {cin}")
    s = stride
    m = -(-k // s)
    b, h, w, _ = x.shape
    wf = jnp.flip(kernel, (0, 1))  # flax does not transpose the kernel: it acts flipped
    y = patch_matmul(x, wf.transpose(2, 0, 1, 3).reshape(cin, k * k * cout))
    y = y.reshape(b, h, w, k, k, cout)
    hb, wb = h + m - 1, w + m - 1
    phases = [[None] * s for _ in range(s)]
    for a in range(k):
        q, r = divmod(a, s)
        for a2 in range(k):
            q2, r2 = divmod(a2, s)
            t = jnp.pad(y[:, :, :, a, a2], ((0, 0), (q, m - 1 - q), (q2, m - 1 - q2), (0, 0)))
            phases[r][r2] = t if phases[r][r2] is None else phases[r][r2] + t
    zero = jnp.zeros((b, hb, wb, cout), x.dtype)
    grid = jnp.stack([jnp.stack([zero if p is None else p for p in row], 3) for row in phases], 3)
    return _blocks_to_image(grid, h, w, k, s)


_TRANSPOSE_METHODS = {"patches": conv_transpose_valid, "col2im": conv_transpose_col2im}


class Conv(nn.Module):
    """``nn.Conv(features, (k, k), strides=(s, s), padding="VALID")`` as patches + matmul;
    ``transpose``: ``nn.ConvTranspose`` with the same arguments, computed by
    ``transpose_method`` ("patches": `conv_transpose_valid`, "col2im":
    `conv_transpose_col2im`; same values)."""

    features: int
    kernel_size: int
    stride: int = 1
    transpose: bool = False
    transpose_method: str = "patches"

    @nn.compact
    def __call__(self, x):
        k = self.kernel_size
        kernel = self.param("kernel", nn.initializers.lecun_normal(),
                            (k, k, x.shape[-1], self.features))
        bias = self.param("bias", nn.initializers.zeros_init(), (self.features,))
        if self.transpose and self.transpose_method not in _TRANSPOSE_METHODS:
            raise ValueError(f"transpose_method must be one of {sorted(_TRANSPOSE_METHODS)}, "
                             f"got {self.transpose_method!r}")
        op = _TRANSPOSE_METHODS[self.transpose_method] if self.transpose else conv_valid
        return op(x, kernel, self.stride) + bias


def ConvTranspose(features: int, kernel_size: int, stride: int = 1,  # noqa: N802
                  method: str = "patches") -> Conv:
    """``nn.ConvTranspose(features, (k, k), strides=(s, s), padding="VALID")``."""
    return Conv(features, kernel_size, stride, transpose=True, transpose_method=method)
