"""Encoder networks: the conv beta-VAE (scene and object) and the object LSTM.

ConvVAE (appendix "Network Architectures", Skew-Fit's 48x48 VAE). Encoder: conv 5x5/3x3/3x3,
16/32/64 filters, strides 3/2/2, VALID padding (48 -> 15 -> 7 -> 3, so 3*3*64 = 576 features),
ReLU; flatten; Dense(feature_dim) (576 scene, 6 object) with no activation (as in the
reference code's CNN head); then Dense heads for the mean and the log-variance. Decoder:
Dense(576) + ReLU -> 3x3x64 -> transposed convs 3x3/3x3/6x6, 32/16/3 filters, strides 2/2/3,
VALID padding (no padding, like PyTorch's padding=0): (3-1)*2+3 = 7, (7-1)*2+3 = 15,
(15-1)*3+6 = 48. The output is the mean of the Gaussian identity-variance decoder, so the
log-likelihood is the squared error (losses.py). It is linear, like the reference code's
(which clamps to [0, 1]): a sigmoid output was tried and gets stuck on segmented images -- it
first learns the black background, saturates, and the vanishing sigmoid gradient never lets
it learn the object (moving-disc test: stuck at the all-black MSE 0.0114; linear reaches 0.001
in 250 steps at beta=1). `decode` clips to [0, 1] for display. The log-variance has
a floor, log(min_variance) + |dense| (reference code; keeps the posterior variance > 0).
`decoder="broadcast"` (not in the paper) replaces the decoder's dense layer and first two
transposed convs with a spatial broadcast decoder (`broadcast_grid`, then two 3x3 convs) before
the last transposed conv; measured in docs/encoders.md ("The cpu preset's encoder settings").

LSTMEncoder: g_psi of "Robustness to Object Occlusions", a 2-layer LSTM (hidden 128) over the
object-VAE latent means, then Dense(out_dim). Auto-encoder target: the paper's equation
L^ae = ||z_t^s - z^hat_t^s||^2 makes the LSTM output reconstruct its *input latent*
(out_dim = object latent size), not the image; the Dense head is that auto-encoder's
"decoder" and its output z_t^s is the final object encoding (reward, goals). The module is
one step, `(carry, x) -> (carry, z)`; `lstm_encode` scans it over a sequence, zeroing the
carry where `resets` is set (episode starts), so one call can span several episodes.
Weights use torch.nn.LSTM's U(-1/sqrt(hidden), 1/sqrt(hidden)) init (reference code).

`vae_model` / `lstm_model` build the module of a config; `encode_mean` and `decode` apply a
VAE's parameters (the latents of rewards, goals and the LSTM's input; images for display).
"""

from __future__ import annotations

import math
from typing import Any

import flax.linen as nn
import jax
import jax.numpy as jnp

from configs.encoders import LSTMConfig, VAEConfig
from roll_jax.common import conv

IMAGE_SHAPE = (48, 48, 3)
_CONV = ((16, 5, 3), (32, 3, 2), (64, 3, 2))  # (filters, kernel, stride), "Network Architectures"
_DECONV = ((32, 3, 2), (16, 3, 2), (3, 6, 3))
_FEATURE_MAP = (3, 3, 64)  # 576 = 3*3*64
# The spatial broadcast decoder (not in the paper; VAEConfig.decoder): the latent tiled over a
# 19x19 grid with two coordinate channels, two VALID 3x3 convs (19 -> 17 -> 15), then Table 3's
# last transposed conv (15 -> 48).
_BROADCAST_GRID = 19
_BROADCAST_CONV = ((32, 3), (32, 3))
DECODERS = ("deconv", "broadcast")
HEAD_INIT_W = 1e-3  # rlkit ConvVAE init_w: the mean / log-variance heads


def _uniform_init(scale: float):
    def init(key, shape, dtype=jnp.float32):
        return jax.random.uniform(key, shape, dtype, -scale, scale)

    return init


def to_float(images: jax.Array) -> jax.Array:
    """uint8 images in [0, 255] -> float32 in [0, 1]; float images pass through as float32."""
    if images.dtype == jnp.uint8:
        return images.astype(jnp.float32) / 255.0
    return images.astype(jnp.float32)


def check_images(images, name: str = "images") -> None:
    """Raise ValueError unless `images` is [..., 48, 48, 3] uint8 or float (static checks only,
    so this works on tracers too and fires at trace time)."""
    shape = tuple(images.shape)
    if len(shape) < 3 or shape[-3:] != IMAGE_SHAPE:
        raise ValueError(f"{name} must have shape [..., 48, 48, 3], got {shape}")
    dtype = jnp.dtype(images.dtype)
    if dtype != jnp.uint8 and not jnp.issubdtype(dtype, jnp.floating):
        raise ValueError(f"{name} must be uint8 (or float in [0, 1]), got dtype {dtype}")


class ConvVAE(nn.Module):
    """``conv_impl``: "matmul" (roll_jax/common/conv.py, one matmul per layer, the fast path on
    XLA:CPU), "matmul_patches" (the same with every transposed conv in the patch form) or
    "lax" (flax's nn.Conv / nn.ConvTranspose, XLA's convolutions); the parameters and values
    are the same either way."""

    latent_dim: int
    feature_dim: int = 576
    min_variance: float = 1e-3
    conv_impl: str = "matmul"
    decoder: str = "deconv"

    def setup(self):
        if self.decoder not in DECODERS:
            raise ValueError(f"decoder must be one of {DECODERS}, got {self.decoder!r}")
        if self.conv_impl in ("matmul", "matmul_patches"):
            self.convs = [conv.Conv(f, k, s) for f, k, s in _CONV]
            # The 3x3 -> 7x7 layer as col2im: its patch form wastes 3.2x the multiply-adds
            # (docs/encoders.md, "Speed on the CPU").
            first = "col2im" if self.conv_impl == "matmul" else "patches"
            self.deconvs = [conv.ConvTranspose(f, k, s, first if i == 0 else "patches")
                            for i, (f, k, s) in enumerate(_DECONV)]
            self.broadcast_convs = [conv.Conv(f, k) for f, k in _BROADCAST_CONV]
        elif self.conv_impl == "lax":
            self.convs = [nn.Conv(f, (k, k), strides=(s, s), padding="VALID")
                          for f, k, s in _CONV]
            self.deconvs = [nn.ConvTranspose(f, (k, k), strides=(s, s), padding="VALID")
                            for f, k, s in _DECONV]
            self.broadcast_convs = [nn.Conv(f, (k, k), padding="VALID")
                                    for f, k in _BROADCAST_CONV]
        else:
            raise ValueError(f"conv_impl must be 'matmul', 'matmul_patches' or 'lax', "
                             f"got {self.conv_impl!r}")
        self.feature = nn.Dense(self.feature_dim)
        # rlkit's ConvVAE: fc1 (mean) and fc2 (log-variance) weights and biases U(-1e-3, 1e-3)
        # (init_w=1e-3), so training starts near the prior with the variance at its floor.
        head_init = _uniform_init(HEAD_INIT_W)
        self.mean_head = nn.Dense(self.latent_dim, kernel_init=head_init, bias_init=head_init)
        self.logvar_head = nn.Dense(self.latent_dim, kernel_init=head_init, bias_init=head_init)
        if self.decoder == "deconv":
            self.dec_fc = nn.Dense(math.prod(_FEATURE_MAP))

    def encode(self, x: jax.Array) -> tuple[jax.Array, jax.Array]:
        """Images [..., 48, 48, 3] (uint8 or float in [0, 1]) -> (mean, logvar) [..., latent]."""
        lead = x.shape[:-3]
        h = to_float(x).reshape((-1,) + IMAGE_SHAPE)
        for conv in self.convs:
            h = nn.relu(conv(h))
        assert h.shape[1:] == _FEATURE_MAP, h.shape
        h = self.feature(h.reshape(h.shape[0], -1))
        mean = self.mean_head(h)
        logvar = math.log(self.min_variance) + jnp.abs(self.logvar_head(h))
        return mean.reshape(lead + (-1,)), logvar.reshape(lead + (-1,))

    def decode(self, z: jax.Array) -> jax.Array:
        """Latents [..., latent] -> Gaussian decoder means [..., 48, 48, 3] (unbounded; the
        data are in [0, 1], clip for display: `encoders.decode` does)."""
        lead = z.shape[:-1]
        z = z.reshape(-1, z.shape[-1])
        if self.decoder == "deconv":
            h = nn.relu(self.dec_fc(z)).reshape((-1,) + _FEATURE_MAP)
            for deconv in self.deconvs[:-1]:
                h = nn.relu(deconv(h))
        else:
            h = broadcast_grid(z, _BROADCAST_GRID)
            for c in self.broadcast_convs:
                h = nn.relu(c(h))
        h = self.deconvs[-1](h)
        assert h.shape[1:] == IMAGE_SHAPE, h.shape
        return h.reshape(lead + IMAGE_SHAPE)

    def __call__(self, x: jax.Array, key: jax.Array) -> tuple[jax.Array, jax.Array, jax.Array]:
        """Reparameterised pass: (reconstruction, mean, logvar)."""
        mean, logvar = self.encode(x)
        z = mean + jnp.exp(0.5 * logvar) * jax.random.normal(key, mean.shape, mean.dtype)
        return self.decode(z), mean, logvar


def broadcast_grid(z: jax.Array, size: int) -> jax.Array:
    """Latents [B, L] -> [B, size, size, L + 2]: each latent tiled over the grid, with the
    grid's x and y coordinates in [-1, 1] as two more channels (Watters et al. 2019, "Spatial
    Broadcast Decoder")."""
    lin = jnp.linspace(-1.0, 1.0, size, dtype=z.dtype)
    yy, xx = jnp.meshgrid(lin, lin, indexing="ij")
    coords = jnp.broadcast_to(jnp.stack([xx, yy], -1), (z.shape[0], size, size, 2))
    tiled = jnp.broadcast_to(z[:, None, None, :], (z.shape[0], size, size, z.shape[-1]))
    return jnp.concatenate([tiled, coords], -1)


# --- LSTM -------------------------------------------------------------------------------------

Carry = tuple  # ((c, h) per layer)


def lstm_zero_carry(hidden: int, layers: int, batch_shape: tuple[int, ...] = ()) -> Carry:
    """All-zero carry: the state at the start of every sequence / episode."""
    z = jnp.zeros(batch_shape + (hidden,), jnp.float32)
    return tuple((z, z) for _ in range(layers))


def _torch_lstm_init(hidden: int):
    """U(-1/sqrt(hidden), 1/sqrt(hidden)), torch.nn.LSTM's init (the reference code's LSTM).
    Also avoids flax's default orthogonal recurrent init, whose batched QR deadlocks XLA:CPU
    when a 2-layer, 128-unit init runs under jit(vmap(...)) over seeds (jaxlib 0.10.2)."""
    return _uniform_init(1.0 / math.sqrt(hidden))


class LSTMEncoder(nn.Module):
    """One step of g_psi: (carry, x [d]) -> (carry, z [out_dim])."""

    hidden: int = 128
    layers: int = 2
    out_dim: int = 6

    def setup(self):
        init = _torch_lstm_init(self.hidden)
        self.cells = [nn.OptimizedLSTMCell(self.hidden, kernel_init=init,
                                           recurrent_kernel_init=init, bias_init=init)
                      for _ in range(self.layers)]
        self.head = nn.Dense(self.out_dim)

    def __call__(self, carry: Carry, x: jax.Array) -> tuple[Carry, jax.Array]:
        new = []
        h = x
        for cell, c in zip(self.cells, carry):
            c, h = cell(c, h)
            new.append(c)
        return tuple(new), self.head(h)

    def zero_carry(self, batch_shape: tuple[int, ...] = ()) -> Carry:
        return lstm_zero_carry(self.hidden, self.layers, batch_shape)

    @staticmethod
    def from_params(params: Any) -> LSTMEncoder:
        """Rebuild the module definition from its parameters (sizes are in the shapes)."""
        p = params["params"]
        hidden, out_dim = p["head"]["kernel"].shape
        layers = sum(1 for k in p if k.startswith("cells_"))
        return LSTMEncoder(hidden=hidden, layers=layers, out_dim=out_dim)


def init_lstm_params(key: jax.Array, model: LSTMEncoder, in_dim: int) -> Any:
    return model.init(key, model.zero_carry(), jnp.zeros((in_dim,), jnp.float32))


def _reset_carry(carry: Carry, reset: jax.Array) -> Carry:
    return jax.tree.map(lambda c: jnp.where(reset, jnp.zeros_like(c), c), carry)


def lstm_step(params: Any, carry: Carry, x: jax.Array, reset: jax.Array | bool = False,
              model: LSTMEncoder | None = None) -> tuple[Carry, jax.Array]:
    """One online step: zero the carry if `reset` (x is an episode's first frame), then step."""
    model = model or LSTMEncoder.from_params(params)
    return model.apply(params, _reset_carry(carry, jnp.asarray(reset)), x)


def lstm_encode(params: Any, seq: jax.Array, resets: jax.Array | None = None,
                model: LSTMEncoder | None = None, carry: Carry | None = None) -> jax.Array:
    """Encode latent sequences [T, d] (or [B, T, d]) -> [T, out_dim] (or [B, T, out_dim]).

    The carry starts at zero (or `carry`) and is re-zeroed before every step whose `resets`
    ([T] / [B, T] bool) is True, so a sequence may cross episode boundaries.
    """
    model = model or LSTMEncoder.from_params(params)
    if seq.ndim == 3:
        if resets is not None and resets.ndim == 1:
            resets = jnp.broadcast_to(resets, seq.shape[:2])
        return jax.vmap(lambda s, r, c: lstm_encode(params, s, r, model, c),
                        in_axes=(0, None if resets is None else 0, None if carry is None else 0)
                        )(seq, resets, carry)
    if seq.ndim != 2:
        raise ValueError(f"seq must be [T, d] or [B, T, d], got shape {seq.shape}")
    if resets is None:
        resets = jnp.zeros(seq.shape[:1], bool)
    if carry is None:
        carry = model.zero_carry()

    def body(c, xr):
        x, r = xr
        c, z = model.apply(params, _reset_carry(c, r), x)
        return c, z

    _, zs = jax.lax.scan(body, carry, (seq.astype(jnp.float32), resets))
    return zs


# --- the models of a config ---------------------------------------------------------------

def vae_model(cfg: VAEConfig) -> ConvVAE:
    return ConvVAE(latent_dim=cfg.latent_dim, feature_dim=cfg.feature_dim,
                   min_variance=cfg.min_variance, conv_impl=cfg.conv_impl,
                   decoder=cfg.decoder)


def lstm_model(cfg: LSTMConfig) -> LSTMEncoder:
    return LSTMEncoder(hidden=cfg.hidden, layers=cfg.layers, out_dim=cfg.out_dim)


def encode_mean(params: Any, cfg: VAEConfig, images: jax.Array) -> jax.Array:
    """Encoder means of images [..., 48, 48, 3] -> [..., latent_dim] (the latents used for
    rewards, goals and the LSTM input)."""
    check_images(images)
    mean, _ = vae_model(cfg).apply(params, images, method=ConvVAE.encode)
    return mean


def decode(params: Any, cfg: VAEConfig, z: jax.Array) -> jax.Array:
    """Latents [..., latent_dim] -> decoded images [..., 48, 48, 3] float, clipped to [0, 1]."""
    return jnp.clip(vae_model(cfg).apply(params, z, method=ConvVAE.decode), 0.0, 1.0)
