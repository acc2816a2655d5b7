"""Parity harness for the jnp MOG2 against ``cv2.createBackgroundSubtractorMOG2``.

``synthetic_video`` makes small test videos that exercise every path of the algorithm (noise,
moving blobs, shadows, global flicker, objects placed later, exact-black pixels, many-valued
pixels for pruning and for replacing the weakest mode); ``compare`` runs both implementations
frame by frame and returns the per-frame fraction of equal mask pixels.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from roll_jax.segmentation import mog2

VIDEO_KINDS = ("noise", "blobs", "shadows", "flicker", "late_object", "black", "multimodal",
               "mixed")

# Parameters of mog2.init and their cv2 setters.
_SETTERS = dict(n_mixtures="setNMixtures", background_ratio="setBackgroundRatio",
                var_threshold_gen="setVarThresholdGen", var_init="setVarInit",
                var_min="setVarMin", var_max="setVarMax", ct="setComplexityReductionThreshold",
                shadow_value="setShadowValue", shadow_threshold="setShadowThreshold")


def synthetic_video(kind: str, t: int = 200, h: int = 32, w: int = 32, c: int = 3,
                    seed: int = 0) -> np.ndarray:
    """uint8[t, h, w, c] video of the given kind (see VIDEO_KINDS)."""
    if kind not in VIDEO_KINDS:
        raise ValueError(f"kind={kind!r}: expected one of {VIDEO_KINDS}")
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    base = rng.uniform(30, 220, size=c) + 25 * np.sin((xx / 5 + yy / 7)[..., None]
                                                     + np.arange(c))
    video = np.repeat(base[None], t, 0)
    noise_sd = 2.0 if kind != "noise" else 6.0
    video = video + rng.normal(0, noise_sd, size=video.shape)

    def blobs(n, radius, value_fn, start=0):
        pos = rng.uniform(0, [h, w], size=(n, 2))
        vel = rng.uniform(-1.5, 1.5, size=(n, 2))
        for i in range(start, t):
            for b in range(n):
                p = (pos[b] + vel[b] * i) % [h, w]
                m = (yy - p[0]) ** 2 + (xx - p[1]) ** 2 < radius ** 2
                video[i][m] = value_fn(video[i][m], b)

    if kind in ("blobs", "mixed"):
        colors = rng.uniform(0, 255, size=(4, c))
        blobs(3, 5.0, lambda v, b: colors[b] + rng.normal(0, 3, size=v.shape))
    if kind in ("shadows", "mixed"):
        blobs(2, 7.0, lambda v, b: v * (0.55 + 0.25 * b))  # darker, same chromaticity
    if kind in ("flicker", "mixed"):
        gain = 1 + 0.15 * np.sin(np.arange(t) / 3.0) + rng.normal(0, 0.03, size=t)
        video = video * gain[:, None, None, None]
    if kind in ("late_object", "mixed"):
        y0, x0 = rng.integers(0, h // 2), rng.integers(0, w // 2)
        video[t // 2:, y0:y0 + h // 3, x0:x0 + w // 3] = rng.uniform(0, 255, size=c)
        video[3 * t // 4:, :h // 4, -w // 4:] *= 0.6  # and a shadow placed later
    if kind in ("black", "mixed"):
        video[:, : h // 4, : w // 4] = 0  # exact black, always
        video[::3, -h // 4:, : w // 4] = 0  # black every third frame
    if kind in ("multimodal", "mixed"):
        # Pixels cycling through several levels: more modes than slots (replacement), then a
        # level that stops appearing (decay and pruning).
        levels = rng.uniform(0, 255, size=(6, c))
        region = (slice(h // 2, h), slice(w // 2, w))
        period = rng.integers(2, 7, size=(h - h // 2, w - w // 2))
        for i in range(t):
            idx = (i // period + (i % 5 == 0)) % (6 if i < 2 * t // 3 else 2)
            video[i][region] = levels[idx] + rng.normal(0, 1.5, size=idx.shape + (c,))
    return np.clip(np.rint(video), 0, 255).astype(np.uint8)


def cv2_subtractor(history: int = 500, var_threshold: float = 16.0,
                   detect_shadows: bool = True, **params):
    """A cv2 MOG2 configured like ``mog2.init(..., **params)``."""
    import cv2

    cv2.ocl.setUseOpenCL(False)  # parity target is OpenCV's CPU path
    sub = cv2.createBackgroundSubtractorMOG2(history, var_threshold, detect_shadows)
    for name, value in params.items():
        getattr(sub, _SETTERS[name])(value)
    return sub


@dataclasses.dataclass
class ParityResult:
    agreement: np.ndarray  # float64[T], fraction of equal mask pixels per frame
    background_equal: float  # fraction of equal getBackgroundImage pixels at the end
    cv2_masks: np.ndarray
    jax_masks: np.ndarray

    @property
    def min(self) -> float:
        return float(self.agreement.min())

    @property
    def mean(self) -> float:
        return float(self.agreement.mean())


def compare(frames: np.ndarray, learning_rates, history: int = 500,
            var_threshold: float = 16.0, detect_shadows: bool = True,
            **params) -> ParityResult:
    """Run cv2 and ``mog2.apply_video`` over frames uint8[T, H, W, C] with per-frame rates."""
    t, h, w, c = frames.shape
    lrs = np.broadcast_to(np.asarray(learning_rates, np.float64), (t,))
    sub = cv2_subtractor(history, var_threshold, detect_shadows, **params)
    ref = np.stack([sub.apply(f if c == 3 else f[..., 0], learningRate=float(lr))
                    for f, lr in zip(frames, lrs)])
    model = mog2.init(h, w, c, history=history, var_threshold=var_threshold,
                      detect_shadows=detect_shadows, **params)
    model, masks = mog2.apply_video(model, frames, lrs)
    masks = np.asarray(masks)
    agreement = (masks == ref).reshape(t, -1).mean(1)
    bg_ref = sub.getBackgroundImage().reshape(h, w, c)
    bg = np.asarray(mog2.background_image(model))
    return ParityResult(agreement, float((bg == bg_ref).mean()), ref, masks)
