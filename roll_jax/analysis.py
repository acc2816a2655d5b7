"""The paper's two representation analyses.

1. "Segmented images give a better reward" (paper Figure 5): for N observations and one goal,
   true object distance (x) against the scene-VAE latent distance and the object latent
   distance (object-VAE of the segmented image, then one LSTM step from the zero state, the
   way a goal image is encoded), with the Spearman rank correlation of each.

       python -m roll_jax.analysis latent-vs-distance --task TASK --ckpt DIR [--out DIR]

2. Occlusion retrieval (appendix A "Occlusion analysis"), hurdle_top: puck-moving
   trajectories; one random frame t >= 1 per trajectory loses 85% of its object pixels; each
   model encodes that frame (the LSTMs with the trajectory's history), the nearest clean frame
   in latent space is retrieved from the pool of all clean frames, and the error is the true
   puck distance between the retrieved frame and the occluded one. Models: (1) LSTM trained
   with the matching loss, (2) the same LSTM trained without it, (3) the object-VAE alone;
   all three on the same object-VAE, trained on the same trajectories. The models are also
   scored along the LSTMs' training (`curve`).

       python -m roll_jax.analysis occlusion --ckpt DIR [--out DIR]

DIR is the output of `python -m roll_jax.pretrain --task TASK --out DIR` (DIR/segmentation,
DIR/encoders, DIR/pretrain.json); --out defaults to DIR/analysis. JSON keys follow docs/architecture.md
("Evaluation files"): `spearman_object`, `spearman_scene`; `error_cm` = {"lstm_matching":
[mean, std], "lstm": [...], "vae": [...]}.

The core functions take encoders as plain callables (images -> latents), so tests can feed
synthetic images and ideal encoders; `model_encoders` and `occlusion_models` build them from
a checkpoint.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json
import os
import sys
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np

from roll_jax import encoders
from roll_jax.goal_encoding import Frozen, GoalEncoder, goal_encoder
from roll_jax.models import lstm_encode

# Appendix A, Fig. S1(a): estimation error of the occluded puck position (cm).
PAPER_ERROR_CM = {"lstm_matching": 1.0, "lstm": 2.2, "vae": 3.1}
OCCLUSION_MODELS = ("lstm_matching", "lstm", "vae")
OCCLUSION_DROP = 0.85  # Appendix A: "removing 85% of the pixels"
# LSTM training steps at which the occlusion command also scores the three models (below
# the run's own length, which is scored too): the auto-encoder LSTM's retrieval changes with
# how far it has learned to copy its input (docs/analysis.md).
CURVE_STEPS = (0, 100, 200, 500, 1000, 2000, 5000)


# ============================================================================ statistics

def rankdata(x) -> np.ndarray:
    """Ranks 1..n of a 1-D array, ties get the average of the ranks they span (like
    scipy.stats.rankdata(method="average"))."""
    x = np.asarray(x, np.float64).ravel()
    n = x.size
    order = np.argsort(x, kind="mergesort")
    xs = x[order]
    starts = np.r_[0, np.flatnonzero(np.diff(xs)) + 1]
    ends = np.r_[starts[1:], n]
    avg = (starts + ends + 1) / 2.0  # mean of the 1-based ranks starts+1 .. ends
    ranks = np.empty(n, np.float64)
    ranks[order] = np.repeat(avg, ends - starts)
    return ranks


def pearson(x, y) -> float:
    """Pearson correlation; NaN when either input is constant."""
    x = np.asarray(x, np.float64).ravel()
    y = np.asarray(y, np.float64).ravel()
    dx, dy = x - x.mean(), y - y.mean()
    den = np.sqrt(np.sum(dx * dx) * np.sum(dy * dy))
    return float(np.sum(dx * dy) / den) if den > 0 else float("nan")


def spearman(x, y) -> float:
    """Spearman rank correlation = Pearson correlation of the (average-tie) ranks."""
    x = np.asarray(x, np.float64).ravel()
    y = np.asarray(y, np.float64).ravel()
    if x.shape != y.shape:
        raise ValueError(f"spearman: x and y must have the same length, got {x.size} and {y.size}")
    if x.size < 2:
        raise ValueError(f"spearman needs at least 2 points, got {x.size}")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
        raise ValueError("spearman: inputs must be finite")
    return pearson(rankdata(x), rankdata(y))


# ============================================================================ helpers

def batched(fn: Callable, x, chunk: int = 512):
    """fn over the leading axis of x in fixed-size chunks (the last one padded, so fn compiles
    at most once); returns a numpy array."""
    x = np.asarray(x)
    n = x.shape[0]
    if n <= chunk:
        return np.asarray(fn(jnp.asarray(x)))
    out = []
    for i in range(0, n, chunk):
        part = x[i:i + chunk]
        m = part.shape[0]
        if m < chunk:
            part = np.concatenate([part, np.repeat(part[-1:], chunk - m, 0)])
        out.append(np.asarray(fn(jnp.asarray(part)))[:m])
    return np.concatenate(out)


def _units(env) -> tuple[str, float]:
    """Axis label and scale for the task's object distance."""
    if env.kind == "door":
        return "door angle distance (rad)", 1.0
    return "object distance (cm)", 100.0


# ============================================================================ 1. latent vs distance

@dataclasses.dataclass(frozen=True)
class ObservationSet:
    """Figure 5's observations and goal, with the renderer's ground-truth labels (0 background,
    1 robot, 2 object) for the visibility reference; numpy arrays."""

    rgb: np.ndarray  # uint8 [n, 48, 48, 3]
    goal_rgb: np.ndarray  # uint8 [48, 48, 3]
    distances: np.ndarray  # [n] env.goal_distance(obs, goal): metres (radians for the door)
    states: np.ndarray  # [n, k] env.object_state
    labels: np.ndarray  # int32 [n, 48, 48]
    goal_labels: np.ndarray  # int32 [48, 48]
    goal_state: np.ndarray  # [k] env.object_state of the goal


def observation_set(env, key, n: int) -> ObservationSet:
    """N observations with the object uniform in its goal space and the hand uniform in its
    box (kinematic `env.place`, rendered), and one goal from `env.sample_goal`."""
    k_goal, k_obs = jax.random.split(key)

    @jax.jit
    def run(k_goal, keys):
        goal = env.sample_goal(k_goal)

        def one(k):
            st = env.random_placement(*jax.random.split(k))
            rgb, labels = env.render_both(st)
            return rgb, labels, env.goal_distance(st, goal), env.object_state(st)

        rgb, labels, dist, pos = jax.vmap(one)(keys)
        goal_rgb, goal_labels = env.render_both(goal)
        return rgb, goal_rgb, dist, pos, labels, goal_labels, env.object_state(goal)

    return ObservationSet(*map(np.asarray, run(k_goal, jax.random.split(k_obs, n))))


# The hand's random placement hides the object in some observations (on the hurdle tasks the
# arm covers the puck's goal space from the camera): an observation shows the object "hidden"
# below HIDDEN_SHARE of the median object pixel count and "whole" from WHOLE_SHARE on.
HIDDEN_SHARE, WHOLE_SHARE = 0.2, 0.8


def object_visibility(labels) -> np.ndarray:
    """Object pixels of each labelled image [n, H, W] over their median -> [n]."""
    px = np.sum(np.asarray(labels) == 2, axis=(-2, -1)).astype(np.float64)
    return px / max(float(np.median(px)), 1.0)


def _centroids(labels) -> np.ndarray:
    obj = (np.asarray(labels) == 2).astype(np.float64)
    rows, cols = np.mgrid[0:obj.shape[-2], 0:obj.shape[-1]]
    w = np.maximum(obj.sum((-2, -1)), 1.0)
    return np.stack([(obj * rows).sum((-2, -1)) / w, (obj * cols).sum((-2, -1)) / w], -1)


def pixel_reference(obs: ObservationSet) -> dict:
    """The Figure 5 and probe statistics of a hand-built encoder with perfect segmentation:
    the centroid (pixels) of the ground-truth object pixels, and where the object is hidden
    the mean centroid of the other observations (the best constant guess). Not a bound on a
    learned encoder, a yardstick: what the observations allow an encoder that sees only the
    object's visible pixels. With `known_reference`'s statistics (`known_*`) beside it."""
    vis = object_visibility(obs.labels)
    hidden = vis < HIDDEN_SHARE
    known = known_reference(obs, hidden)  # refuses observations that all hide the object
    c = _centroids(obs.labels)
    c = np.where(hidden[:, None], c[~hidden].mean(0), c)
    d = np.linalg.norm(c - _centroids(obs.goal_labels[None])[0], axis=-1)
    return {"reference_spearman_object": spearman(obs.distances, d),
            "reference_pairwise_spearman": pairwise_spearman(c, obs.states),
            "reference_r2": position_r2(c, obs.states),
            **known,
            "share_object_hidden": float(hidden.mean()),
            "share_object_partly_hidden": float(((vis >= HIDDEN_SHARE) & (vis < WHOLE_SHARE)).mean())}


def known_reference(obs: ObservationSet, hidden) -> dict:
    """The same statistics for an encoder that knows the object's true state wherever it
    shows (`hidden` [n] False) and gives hidden objects the shown ones' mean state: what the
    observations allow an encoder that sees through the arm's partial occlusions, where
    `pixel_reference`'s centroid sees only the visible pixels."""
    hidden = np.asarray(hidden, bool)
    if hidden.all():
        raise ValueError(f"every one of the {len(hidden)} observations hides the object")
    guess = obs.states[~hidden].mean(0)
    est = np.where(hidden[:, None], guess, obs.states)
    # Shown objects are where they are: their distance to the goal is the true one.
    d = np.where(hidden, np.linalg.norm(guess - obs.goal_state), obs.distances)
    return {"known_spearman_object": spearman(obs.distances, d),
            "known_pairwise_spearman": pairwise_spearman(est, obs.states),
            "known_r2": position_r2(est, obs.states)}


def _r2(predicted, y) -> float:
    """R^2 of predictions of y [n, k], all coordinates pooled."""
    return float(1.0 - np.sum((predicted - y) ** 2) / np.sum((y - y.mean(0)) ** 2))


def _with_bias(z) -> np.ndarray:
    return np.concatenate([z, np.ones((len(z), 1))], 1)


def position_r2(latents, positions) -> float:
    """R^2 of a least-squares affine fit of the object states [n, k] from latents [n, d]
    (all coordinates pooled): how linearly the latents encode where the object is."""
    x = _with_bias(np.asarray(latents, np.float64))
    y = np.asarray(positions, np.float64)
    coef, *_ = np.linalg.lstsq(x, y, rcond=None)
    return _r2(x @ coef, y)


def _affine_cv_r2(features, y, folds: int) -> float:
    """Held-out R^2 of an affine least-squares fit, `folds`-fold cross-validated (fold = index
    mod folds)."""
    x = _with_bias(features)
    fold = np.arange(len(y)) % folds
    predicted = np.empty_like(y)
    for f in range(folds):
        coef, *_ = np.linalg.lstsq(x[fold != f], y[fold != f], rcond=None)
        predicted[fold == f] = x[fold == f] @ coef
    return _r2(predicted, y)


def position_r2_nonlinear(latents, positions, folds: int = 5, k: int = 10) -> dict:
    """Whether the latents hold the object's state although an affine fit misses it: held-out
    R^2 of an affine fit ("affine_cv", `position_r2` without the in-sample fit), of an affine
    fit on the latents and their pairwise products ("quadratic_cv"), and of the mean state of
    each latent's k nearest other latents ("knn"). A curved code scores low on the first and
    high on the other two; a code without the state scores low on all three."""
    z = np.asarray(latents, np.float64)
    y = np.asarray(positions, np.float64)
    if len(z) <= max(folds, k) or len(z) != len(y):
        raise ValueError(f"need matching latents and states, more than max(folds, k) = "
                         f"{max(folds, k)}; got {len(z)} latents and {len(y)} states")
    i, j = np.triu_indices(z.shape[1])
    quad = np.concatenate([z, z[:, i] * z[:, j]], 1)
    sq = np.sum(z * z, 1)
    d = sq[:, None] + sq[None] - 2.0 * z @ z.T  # [n, n], not [n, n, d]: --n may be large
    np.fill_diagonal(d, np.inf)
    knn = y[np.argpartition(d, k, axis=1)[:, :k]].mean(1)
    return {"affine_cv": _affine_cv_r2(z, y, folds), "quadratic_cv": _affine_cv_r2(quad, y, folds),
            "knn": _r2(knn, y)}


def pairwise_spearman(latents, positions, max_n: int = 300) -> float:
    """Spearman of latent distance vs object-state distance over all pairs of the first
    `max_n` observations."""
    z = np.asarray(latents, np.float64)[:max_n]
    y = np.asarray(positions, np.float64)[:max_n]
    i, j = np.triu_indices(len(z), 1)
    return spearman(np.linalg.norm(y[i] - y[j], axis=-1), np.linalg.norm(z[i] - z[j], axis=-1))


def latent_distances(encode: Callable, obs_rgb, goal_rgb) -> np.ndarray:
    """||encode(obs) - encode(goal)|| per observation; encode: images [B, ...] -> [B, d]."""
    z = np.asarray(encode(np.asarray(obs_rgb)), np.float64)
    zg = np.asarray(encode(np.asarray(goal_rgb)[None]), np.float64)[0]
    return np.linalg.norm(z - zg, axis=-1)


def latent_vs_distance(obs_rgb, goal_rgb, distances, encode_scene: Callable,
                       encode_object: Callable) -> dict:
    """Figure 5 data and its Spearman correlations.

    encode_scene / encode_object: uint8 images [B, 48, 48, 3] -> latents [B, d] (the
    scene-VAE mean of the whole image; the object encoding of the segmented image)."""
    distances = np.asarray(distances, np.float64)
    scene = latent_distances(encode_scene, obs_rgb, goal_rgb)
    obj = latent_distances(encode_object, obs_rgb, goal_rgb)
    return {
        "n": int(distances.size),
        "spearman_object": spearman(distances, obj),
        "spearman_scene": spearman(distances, scene),
        "pearson_object": pearson(distances, obj),
        "pearson_scene": pearson(distances, scene),
        "object_distance": distances,
        "object_latent_distance": obj,
        "scene_latent_distance": scene,
    }


def write_latent_vs_distance(result: dict, out_dir: str, task: str,
                             x_label: str = "object distance (cm)", x_scale: float = 100.0,
                             extra: dict | None = None) -> tuple[str, str]:
    """Scatter plot PNG (both latent distances, each divided by its maximum so they share an
    axis) and JSON (summary + the plotted arrays). Returns (png, json) paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    os.makedirs(out_dir, exist_ok=True)
    png = os.path.join(out_dir, f"latent_vs_distance_{task}.png")
    js = os.path.join(out_dir, f"latent_vs_distance_{task}.json")
    x = np.asarray(result["object_distance"]) * x_scale

    def norm(v):
        v = np.asarray(v, np.float64)
        m = v.max() if v.size else 0.0
        return v / m if m > 0 else v

    fig, ax = plt.subplots(figsize=(4.5, 3.6))
    ax.scatter(x, norm(result["scene_latent_distance"]), s=8, alpha=0.6, color="tab:orange",
               label=f"scene-VAE latent (Spearman {result['spearman_scene']:.2f})")
    ax.scatter(x, norm(result["object_latent_distance"]), s=8, alpha=0.6, color="tab:blue",
               label=f"object latent (Spearman {result['spearman_object']:.2f})")
    ax.set_xlabel(x_label)
    ax.set_ylabel("latent distance / max")
    ax.set_title(f"{task}: latent vs object distance (n={result['n']})", fontsize=9)
    ax.legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    plt.close(fig)

    summary = {"task": task, "n": result["n"],
               "spearman_object": _f(result["spearman_object"]),
               "spearman_scene": _f(result["spearman_scene"]),
               "pearson_object": _f(result["pearson_object"]),
               "pearson_scene": _f(result["pearson_scene"]),
               **(extra or {}),
               "object_distance": _list(result["object_distance"]),
               "object_latent_distance": _list(result["object_latent_distance"]),
               "scene_latent_distance": _list(result["scene_latent_distance"])}
    with open(js, "w") as f:
        json.dump(summary, f, indent=1)
    return png, js


def _f(v) -> float | None:
    v = float(v)
    return v if np.isfinite(v) else None


def _list(a) -> list:
    return [round(float(v), 6) for v in np.asarray(a).ravel()]


@functools.partial(jax.jit, static_argnames=("cfg",))
def _scene_encode(params, cfg, rgb):
    return encoders.encode_mean(params, cfg, rgb)


@functools.partial(jax.jit, static_argnames=("enc",))
def _object_encode(enc: GoalEncoder, frozen, scene_params, lstm_params, rgb):
    return enc.encode_goal_images(frozen, scene_params, lstm_params, rgb)


@functools.partial(jax.jit, static_argnames=("enc",))
def _frame_encode(enc: GoalEncoder, frozen, scene_params, rgb):
    return enc.frame_latents(frozen, scene_params, enc.goal_images(frozen, rgb))


def model_encoders(cfg, pre, seg, chunk: int = 512) -> tuple[Callable, Callable]:
    """(encode_scene, encode_object) of a pretrained checkpoint: the scene-VAE mean of the
    image, and the goal encoding of the config's GoalEncoder (segment -> object-VAE -> one
    LSTM step for ROLL)."""
    enc = goal_encoder(cfg)
    frozen = Frozen(seg=seg, object_vae=None if pre.object_vae is None else pre.object_vae.params)
    scene_params = pre.scene_vae.params
    lstm_params = None if pre.lstm is None else pre.lstm.params

    def encode_scene(rgb):
        return batched(lambda x: _scene_encode(scene_params, cfg.scene, x), rgb, chunk)

    def encode_object(rgb):
        return batched(lambda x: _object_encode(enc, frozen, scene_params, lstm_params, x),
                        rgb, chunk)

    return encode_scene, encode_object


# ============================================================================ 2. occlusion

HURDLE_TASKS = ("hurdle_bottom", "hurdle_top")  # with a path around a wall (scenes.hurdle_path)
HAND_BEHIND = 0.057  # puck radius 0.04 + claw radius 0.015 + 2 mm: the hand touching the puck


def puck_paths(key, task: str, n: int, horizon: int, speed=(0.003, 0.008), jitter: float = 0.005):
    """Kinematic pushes along the task's hurdle path (`envs_mjx.scenes.hurdle_path`): per
    trajectory a random start on the path, a random speed (m/step, +-30% per-step noise)
    and a constant random offset of up to `jitter` per axis; the puck stops at the end of
    the path. The hand stays just behind the
    puck (against the direction of motion), as when pushing it.

    Returns numpy (puck xy [n, T, 2], hand xy [n, T, 2])."""
    from envs_mjx.scenes import hurdle_path

    way = np.asarray(hurdle_path(task), np.float64)  # ValueError for a task without a hurdle
    rng = np.random.default_rng(int(jax.random.randint(key, (), 0, 2**31 - 1)))
    seg = np.diff(way, axis=0)
    seg_len = np.linalg.norm(seg, axis=1)
    cum = np.r_[0.0, np.cumsum(seg_len)]
    total = cum[-1]
    v = rng.uniform(*speed, size=(n, 1))
    steps = v * rng.uniform(0.7, 1.3, size=(n, horizon))
    s0 = rng.uniform(0.0, total - 0.05, size=(n, 1))
    s = np.clip(s0 + np.cumsum(steps, axis=1) - steps[:, :1], 0.0, total)
    i = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(seg) - 1)
    frac = (s - cum[i]) / seg_len[i]
    offset = rng.uniform(-jitter, jitter, size=(n, 1, 2))
    puck = way[i] + frac[..., None] * seg[i] + offset
    tangent = seg[i] / seg_len[i][..., None]
    hand = puck - HAND_BEHIND * tangent
    return puck.astype(np.float32), hand.astype(np.float32)


def render_pushes(env, puck, hand, chunk: int = 256) -> np.ndarray:
    """uint8 [n, T, 48, 48, 3]: each (puck xy, hand xy) placed with `env.place` and rendered."""
    lo, hi = env.hand_bounds
    shape = puck.shape[:-1]
    hand3 = np.concatenate([hand.reshape(-1, 2), np.full((hand[..., 0].size, 1), lo[2])], -1)
    hand3 = np.clip(hand3, lo, hi).astype(np.float32)
    both = np.concatenate([hand3, puck.reshape(-1, 2)], -1)

    @jax.jit
    def run(x):
        return jax.vmap(lambda r: env.render(env.place(r[:3], r[3:])))(x)

    return batched(run, both, chunk).reshape(shape + (48, 48, 3))


def occlude_frames(key, images, masks, drop: float = OCCLUSION_DROP, min_t: int = 1):
    """`encoders.occlusion_frames` as numpy: (t [B], occluded frames [B, 48, 48, 3]) of
    segmented uint8 images [B, T, 48, 48, 3] with masks [B, T, 48, 48] (or None)."""
    t, occ = encoders.occlusion_frames(key, jnp.asarray(images),
                                       None if masks is None else jnp.asarray(masks), min_t, drop)
    return np.asarray(t), np.asarray(occ)


def retrieval_errors(clean_codes, query_codes, positions, occ_t, exclude_own: bool = False
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Nearest clean frame (L2 in code space, over all B*T frames, or with `exclude_own` over
    the frames of the other trajectories) of each query; returns (position error per query
    [B] in the units of `positions`, retrieved flat index [B]).

    clean_codes [B, T, d]; query_codes [B, d]; positions [B, T, k]; occ_t [B]."""
    clean = np.asarray(clean_codes, np.float64)
    b, t_len, d = clean.shape
    pool = clean.reshape(b * t_len, d)
    q = np.asarray(query_codes, np.float64)
    d2 = (np.sum(q * q, 1)[:, None] - 2.0 * q @ pool.T + np.sum(pool * pool, 1)[None, :])
    if exclude_own:
        d2[np.arange(b * t_len)[None, :] // t_len == np.arange(b)[:, None]] = np.inf
    nn = np.argmin(d2, axis=1)
    pos = np.asarray(positions, np.float64)
    truth = pos[np.arange(b), np.asarray(occ_t)]
    err = np.linalg.norm(pos.reshape(b * t_len, -1)[nn] - truth, axis=-1)
    return err, nn


def occlusion_queries(key, images, masks, frame_encoder: Callable,
                      drop: float = OCCLUSION_DROP, min_t: int = 1):
    """The queries of `occlusion_retrieval`: (per-frame latents of the clean trajectories
    [B, T, d], the same with frame occ_t[b] replaced by its occluded latent, occ_t [B])."""
    images = np.asarray(images)
    b, t_len = images.shape[:2]
    occ_t, occluded = occlude_frames(key, images, masks, drop, min_t)
    lat = np.asarray(frame_encoder(images.reshape((-1,) + images.shape[2:])))
    lat = lat.reshape(b, t_len, -1)
    occ_seq = lat.copy()
    occ_seq[np.arange(b), occ_t] = np.asarray(frame_encoder(occluded))
    return lat, occ_seq, occ_t


def score_heads(lat, occ_seq, occ_t, positions, heads: dict[str, Callable],
                scale: float = 100.0, exclude_own: bool = False) -> dict:
    """Retrieval error of each head on the queries of `occlusion_queries` (keys as
    `occlusion_retrieval`'s; `exclude_own`: retrieve from the other trajectories only)."""
    b, t_len = lat.shape[:2]
    pos = np.asarray(positions, np.float64)
    truth = pos[np.arange(b), occ_t]
    chance = np.linalg.norm(pos.reshape(1, b * t_len, -1) - truth[:, None], axis=-1).mean()
    out = {"error_cm": {}, "median_cm": {}, "errors_cm": {}, "retrieved": {}, "occ_t": occ_t,
           "n_queries": int(b), "pool_size": int(b * t_len), "chance_cm": float(chance * scale)}
    for name, head in heads.items():
        clean = np.asarray(head(lat))
        query = np.asarray(head(occ_seq))[np.arange(b), occ_t]
        err, nn = retrieval_errors(clean, query, positions, occ_t, exclude_own)
        err = err * scale
        out["errors_cm"][name] = err
        out["retrieved"][name] = nn
        out["error_cm"][name] = [float(err.mean()), float(err.std())]
        out["median_cm"][name] = float(np.median(err))
    return out


def occlusion_retrieval(key, images, masks, positions, frame_encoder: Callable,
                        heads: dict[str, Callable], drop: float = OCCLUSION_DROP,
                        min_t: int = 1, scale: float = 100.0) -> dict:
    """Appendix A. images: segmented uint8 [B, T, 48, 48, 3] (clean trajectories); masks
    their object masks [B, T, 48, 48] (or None); positions the true puck xy [B, T, 2] (m).

    frame_encoder: images [N, 48, 48, 3] -> per-frame latents [N, d] (the object-VAE mean);
    heads: name -> f(latents [B, T, d]) -> codes [B, T, d'] (an LSTM over each trajectory, or
    the identity for the VAE alone). For each trajectory one frame t >= min_t is occluded
    (`drop` of its object pixels removed); its code is the head's output at t on the
    trajectory with frame t replaced; the nearest clean code among all B*T frames is
    retrieved. Returns {"error_cm": {name: [mean, std]}, "median_cm": {name: median},
    "errors_cm": {name: [B]}, "occ_t",
    "retrieved", "n_queries", "pool_size", "chance_cm"} (errors in positions' units times
    `scale`; chance_cm: the mean error of a uniformly random pick from the pool)."""
    lat, occ_seq, occ_t = occlusion_queries(key, images, masks, frame_encoder, drop, min_t)
    return score_heads(lat, occ_seq, occ_t, positions, heads, scale)


def paired_difference(a, b) -> list[float]:
    """[mean, standard error] of a - b over paired per-query errors."""
    d = np.asarray(a, np.float64) - np.asarray(b, np.float64)
    return [float(d.mean()), float(d.std(ddof=1) / np.sqrt(d.size)) if d.size > 1 else 0.0]


def ordering_holds(res: dict) -> bool:
    """The paper's ordering LSTM + matching < LSTM < object-VAE by mean error, each step
    separated by more than two standard errors of the paired difference."""
    e = res["errors_cm"]
    return all(d[0] + 2.0 * d[1] < 0.0 for d in (paired_difference(e["lstm_matching"], e["lstm"]),
                                                 paired_difference(e["lstm"], e["vae"])))


# --- the three models --------------------------------------------------------------------
@functools.partial(jax.jit, static_argnames=("cfg",))
def _finetune_vae(state, key, images, masks, cfg):
    return encoders.vae_fit_epoch(state, key, images, cfg, masks)


def finetune_vae(key, state: encoders.ModelState, cfg, images, masks, n_steps: int,
                 batch: int | None = None, chunk: int = 100):
    """`n_steps` object-VAE steps (its config's loss: beta-VAE + VAE matching; the trajectory
    frames have no arm-pair partners) on frames [N, 48, 48, 3] with object masks [N, 48, 48].
    Returns (state, losses [n_steps])."""
    images, masks = jnp.asarray(images), jnp.asarray(masks)
    batch = batch or cfg.batch_size
    hist = []
    for i in range(0, n_steps, chunk):
        c = dataclasses.replace(cfg, batch_size=batch, batches_per_epoch=min(chunk, n_steps - i),
                                arm_pair_coef=0.0)
        state, m = _finetune_vae(state, jax.random.fold_in(key, i), images, masks, c)
        hist.append(np.asarray(m["loss"]))
    return state, (np.concatenate(hist) if hist else np.zeros((0,)))


@functools.partial(jax.jit, static_argnames=("vae_cfg", "lstm_cfg", "matching", "n_steps", "batch"))
def _train_lstm(state, key, vae_params, latents, images, masks, vae_cfg, lstm_cfg,
                matching: bool, n_steps: int, batch: int):
    n = latents.shape[0]

    def body(st, k):
        k_idx, k_occ, k_step = jax.random.split(k, 3)
        idx = jax.random.randint(k_idx, (batch,), 0, n)
        occ = None
        if matching:
            occ = encoders.make_occlusion(k_occ, vae_params, vae_cfg, images[idx], lstm_cfg,
                                          masks[idx])
        st, m = encoders.lstm_train_step(st, k_step, latents[idx], lstm_cfg, occ)
        return st, m["loss"]

    return jax.lax.scan(body, state, jax.random.split(key, n_steps))


def train_occlusion_lstms(key, vae_params, vae_cfg, lstm_cfg, images, masks, n_steps: int,
                          batch: int = 25, chunk: int = 100, snapshot_steps=()):
    """Two LSTMs from the same initialisation on the same batches of the same trajectories
    (segmented uint8 [B, T, 48, 48, 3], masks [B, T, 48, 48]) over the same object-VAE: one
    with auto-encoder + matching loss (synthetic occlusion from `make_occlusion`, drop
    lstm_cfg.occlusion_drop), one with the auto-encoder loss only.

    Returns ({"lstm_matching": params, "lstm": params}, {name: losses [n_steps]},
    {step: {name: params}} after each of `snapshot_steps` (0 = the initialisation))."""
    bad = [s for s in snapshot_steps if not 0 <= s <= n_steps]
    if bad:
        raise ValueError(f"snapshot_steps {bad} outside 0..n_steps={n_steps}")
    images, masks = jnp.asarray(images), jnp.asarray(masks)
    latents = encode_frames(vae_params, vae_cfg, images)
    k_init, k_train = jax.random.split(key)
    init = encoders.init_lstm(k_init, lstm_cfg, latents.shape[-1])
    # Segments of `chunk` steps, also cut at the snapshots; a segment's batches come from its
    # first step's key, so snapshots at multiples of `chunk` leave the training unchanged.
    starts = sorted(set(range(0, n_steps, chunk)) | {s for s in snapshot_steps if s < n_steps})
    params, hist = {}, {}
    snapshots = {int(s): {} for s in snapshot_steps}
    for name, matching in (("lstm_matching", True), ("lstm", False)):
        st, h = init, []
        for i, end in zip(starts, starts[1:] + [n_steps]):
            if i in snapshots:
                snapshots[i][name] = st.params
            st, l = _train_lstm(st, jax.random.fold_in(k_train, i), vae_params, latents, images,
                                masks, vae_cfg, lstm_cfg, matching, end - i, batch)
            h.append(np.asarray(l))
        if n_steps in snapshots:
            snapshots[n_steps][name] = st.params
        params[name] = st.params
        hist[name] = np.concatenate(h) if h else np.zeros((0,))
    return params, hist, snapshots


def encode_frames(vae_params, vae_cfg, images, chunk: int = 1024) -> jnp.ndarray:
    """Object-VAE means of images [..., 48, 48, 3] -> [..., d] (chunked)."""
    images = np.asarray(images)
    lead = images.shape[:-3]
    flat = images.reshape((-1,) + images.shape[-3:])
    z = batched(lambda x: _scene_encode(vae_params, vae_cfg, x), flat, chunk)
    return jnp.asarray(z.reshape(lead + (-1,)))


_lstm_codes = jax.jit(lambda p, z: lstm_encode(p, z))  # one program for every set of weights


def occlusion_models(vae_params, vae_cfg, lstm_params: dict) -> tuple[Callable, dict]:
    """(frame_encoder, heads) for `occlusion_retrieval`: the object-VAE mean per frame; the
    two LSTMs over each trajectory (from the zero state) and the identity for the VAE alone."""
    def frame_encoder(x):
        return np.asarray(encode_frames(vae_params, vae_cfg, x))

    heads = {name: functools.partial(lambda p, z: np.asarray(_lstm_codes(p, jnp.asarray(z))), p)
             for name, p in lstm_params.items()}
    heads["vae"] = lambda z: np.asarray(z)
    return frame_encoder, heads


def write_occlusion(result: dict, out_dir: str, task: str, extra: dict | None = None
                    ) -> tuple[str, str]:
    """Bar plot (mean +- std per model, paper values as markers) and JSON."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    os.makedirs(out_dir, exist_ok=True)
    png = os.path.join(out_dir, f"occlusion_{task}.png")
    js = os.path.join(out_dir, f"occlusion_{task}.json")
    names = list(result["error_cm"])
    labels = {"lstm_matching": "LSTM +\nmatching loss", "lstm": "LSTM", "vae": "object-VAE"}
    mean = [result["error_cm"][k][0] for k in names]
    std = [result["error_cm"][k][1] for k in names]
    fig, ax = plt.subplots(figsize=(4.2, 3.4))
    xs = np.arange(len(names))
    ax.bar(xs, mean, yerr=std, capsize=4, color=["tab:blue", "tab:orange", "tab:green"][:len(names)],
           alpha=0.8, label="this run")
    paper = [PAPER_ERROR_CM.get(k, np.nan) for k in names]
    ax.scatter(xs, paper, marker="D", s=30, color="crimson", zorder=3, label="paper (App. A)")
    if result.get("chance_cm") is not None:
        ax.axhline(result["chance_cm"], color="grey", ls="--", lw=1, label="random frame")
    ax.set_xticks(xs)
    ax.set_xticklabels([labels.get(k, k) for k in names], fontsize=8)
    ax.set_ylabel("puck position error (cm)")
    ax.set_title(f"{task}: occluded-frame retrieval (n={result['n_queries']})", fontsize=9)
    ax.set_ylim(bottom=0)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    plt.close(fig)
    summary = {"task": task, "error_cm": result["error_cm"], "median_cm": result["median_cm"],
               "n_queries": result["n_queries"], "pool_size": result["pool_size"],
               "chance_cm": result.get("chance_cm"),
               "paper_error_cm": PAPER_ERROR_CM, **(extra or {}),
               "errors_cm": {k: _list(v) for k, v in result["errors_cm"].items()},
               "occ_t": [int(t) for t in result["occ_t"]]}
    with open(js, "w") as f:
        json.dump(summary, f, indent=1)
    return png, js


def curve_row(step: int, res: dict, hist: dict, others: dict | None = None,
              clean: dict | None = None, window: int = 20) -> dict:
    """One point of the occlusion command's curve: `res` (`score_heads`) after `step` LSTM
    steps, with the paired differences, the share of queries for which the auto-encoder LSTM
    retrieves the very frame the object-VAE does, each LSTM's mean training loss over the
    `window` steps before (None at step 0), `others` (`score_heads` on the other
    trajectories' frames) under "other_trajectories" and `clean` (the same for the clean
    frames at the occluded steps) under "clean_frames"."""
    e, r = res["errors_cm"], res["retrieved"]
    extra = {} if others is None else {"other_trajectories": {
        "error_cm": others["error_cm"], "median_cm": others["median_cm"],
        "ordering_holds": ordering_holds(others)}}
    if clean is not None:
        extra["clean_frames"] = {"error_cm": clean["error_cm"], "median_cm": clean["median_cm"]}
    return {"lstm_steps": int(step), "error_cm": res["error_cm"], "median_cm": res["median_cm"],
            **extra,
            "lstm_matching_minus_lstm_cm": paired_difference(e["lstm_matching"], e["lstm"]),
            "lstm_minus_vae_cm": paired_difference(e["lstm"], e["vae"]),
            "lstm_retrieves_vae_frame": float(np.mean(r["lstm"] == r["vae"])),
            "ordering_holds": ordering_holds(res),
            "loss": {k: (float(np.mean(np.asarray(h)[max(0, step - window):step])) if step
                         else None) for k, h in hist.items()}}


def write_occlusion_curve(curve: list[dict], out_dir: str, task: str) -> str:
    """Mean retrieval error of the three models against the LSTMs' training steps -> PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    steps = np.array([c["lstm_steps"] for c in curve], np.float64)
    fig, ax = plt.subplots(figsize=(5.2, 3.8))
    styles = {"lstm_matching": ("LSTM + matching loss", "tab:blue"),
              "lstm": ("LSTM", "tab:orange"), "vae": ("object-VAE", "tab:green")}
    for name, (label, color) in styles.items():
        mean = np.array([c["error_cm"][name][0] for c in curve])
        ax.plot(steps, mean, "o-", color=color, label=label, ms=4)
        ax.axhline(PAPER_ERROR_CM[name], color=color, ls=":", lw=1)
        if all("other_trajectories" in c for c in curve):
            other = [c["other_trajectories"]["error_cm"][name][0] for c in curve]
            ax.plot(steps, other, "s--", color=color, ms=3, lw=1, alpha=0.7,
                    label=f"{label}, other trajectories' frames")
    ax.set_xscale("symlog", linthresh=100)
    ax.set_xlabel("LSTM training steps (0: the shared initialisation)")
    ax.set_ylabel("mean puck position error (cm)")
    ax.set_title(f"{task}: retrieval along the LSTMs' training (dotted: paper)", fontsize=9)
    ax.legend(fontsize=6)
    ax.set_ylim(bottom=0)
    fig.tight_layout()
    os.makedirs(out_dir, exist_ok=True)
    png = os.path.join(out_dir, f"occlusion_curve_{task}.png")
    fig.savefig(png, dpi=120)
    plt.close(fig)
    return png


# ============================================================================ checkpoints / CLI

def load_checkpoint(ckpt: str, task: str, preset: str | None = None):
    """(cfg, Pretrained, seg params) from a `roll_jax.pretrain --out` directory. The preset is
    read from DIR/pretrain.json when not given (it sets the LSTM training config), and so are
    the pretraining's `--set` overrides."""
    from roll_jax import pretrain
    from roll_jax.segmentation import pipeline

    cfg = checkpoint_config(ckpt, task, preset)
    pre = pretrain.load(os.path.join(ckpt, "encoders"), cfg)
    seg, _ = pipeline.load(os.path.join(ckpt, "segmentation"), task)
    return cfg, pre, seg


def checkpoint_config(ckpt: str, task: str, preset: str | None = None):
    """The ROLL config a `roll_jax.pretrain --out` directory was made with: its preset (or
    `preset`) and its `--set` overrides, both from DIR/pretrain.json."""
    from roll_jax.train import build_config

    return build_config(task, "roll", checkpoint_preset(ckpt, task, preset),
                        overrides=_pretrain_info(ckpt).get("overrides", []))


def _pretrain_info(ckpt: str) -> dict:
    meta = os.path.join(ckpt, "pretrain.json")
    if not os.path.exists(meta):
        return {}
    with open(meta) as f:
        return json.load(f)


def checkpoint_preset(ckpt: str, task: str | None = None, preset: str | None = None) -> str:
    """`preset`, or the one a `roll_jax.pretrain --out` directory was made with
    (DIR/pretrain.json; "paper" without one); refuses a checkpoint of another `task`."""
    info = _pretrain_info(ckpt)
    if task is not None and info.get("task") not in (None, task):
        raise ValueError(f"checkpoint {ckpt} was pretrained for task {info['task']!r}, "
                         f"not {task!r}")
    return preset or info.get("preset", "paper")


def goal_mask_scores(seg, obs: ObservationSet) -> dict:
    """How the segmentation masks the goal image, against the renderer's labels: every
    observation is compared with that one code, so a goal whose object is half masked away
    (pickup's cube held in the gripper) misplaces the whole ranking."""
    from roll_jax.segmentation import pipeline

    labels = jnp.asarray(obs.goal_labels)[None]
    scores = pipeline.mask_scores(pipeline.segment(seg, jnp.asarray(obs.goal_rgb)[None]), labels)
    return {"goal_object_pixels": int((obs.goal_labels == 2).sum()),
            "goal_mask_iou": round(float(scores["iou"][0]), 4),
            "goal_mask_robot_leakage": round(float(scores["robot_leakage"][0]), 4)}


def run_latent_vs_distance(task: str, ckpt: str, out: str, n: int = 500, seed: int = 0,
                           preset: str | None = None) -> dict:
    import envs_mjx

    cfg, pre, seg = load_checkpoint(ckpt, task, preset)
    env = envs_mjx.make(task)
    obs_set = observation_set(env, jax.random.PRNGKey(seed), n)
    obs, goal, dist, pos = obs_set.rgb, obs_set.goal_rgb, obs_set.distances, obs_set.states
    encode_scene, encode_object = model_encoders(cfg, pre, seg)
    res = latent_vs_distance(obs, goal, dist, encode_scene, encode_object)
    # The object-VAE itself, on these held-out segmented images: its means against the
    # object's state (position; door: angle).
    enc = goal_encoder(cfg)
    frozen = Frozen(seg=seg, object_vae=pre.object_vae.params)
    means = batched(lambda x: _frame_encode(enc, frozen, pre.scene_vae.params, x), obs, 512)
    scene = encode_scene(obs)  # what the policy sees must locate the object too
    probe = {"object_vae_r2": position_r2(means, pos),
             "object_vae_pairwise_spearman": pairwise_spearman(means, pos),
             "object_vae_latent_std": [round(float(v), 4) for v in np.std(means, 0)],
             "scene_vae_r2": position_r2(scene, pos),
             "scene_vae_latent_std": [round(float(v), 4) for v in np.std(scene, 0)]}
    # The same statistics on the observations that show the whole object, beside the
    # perfect-segmentation yardstick on all of them; Fig. 5 also without the observations
    # where the object is hidden (no single image locates it there).
    vis = object_visibility(obs_set.labels)
    whole, shown = vis >= WHOLE_SHARE, vis >= HIDDEN_SHARE
    probe.update(pixel_reference(obs_set))
    probe.update(goal_mask_scores(seg, obs_set))
    probe.update({"shown_object_spearman_object": spearman(dist[shown],
                                                           res["object_latent_distance"][shown]),
                  "whole_object_spearman_object": spearman(dist[whole],
                                                           res["object_latent_distance"][whole]),
                  "whole_object_vae_r2": position_r2(means[whole], pos[whole]),
                  "whole_object_vae_pairwise_spearman": pairwise_spearman(means[whole],
                                                                          pos[whole])})
    # Is an r2 short of 1 missing information or only an affine map (a curved latent)?
    for name, m in (("object_vae", slice(None)), ("whole_object_vae", whole)):
        probe.update({f"{name}_r2_{k}": v for k, v in
                      position_r2_nonlinear(means[m], pos[m]).items()})
    x_label, x_scale = _units(env)
    png, js = write_latent_vs_distance(res, out, task, x_label, x_scale,
                                       extra={"preset": cfg.preset, "ckpt": os.path.abspath(ckpt),
                                              "seed": seed, **probe})
    summary = {k: res[k] for k in ("n", "spearman_object", "spearman_scene")}
    return {**summary, **probe, "task": task, "png": png, "json": js}


def run_occlusion(ckpt: str, out: str, task: str = "hurdle_top", n_train: int = 64,
                  n_eval: int = 64, horizon: int | None = None, lstm_steps: int = 200,
                  vae_steps: int = 200, batch: int = 25, drop: float = OCCLUSION_DROP,
                  seed: int = 0, preset: str | None = None) -> dict:
    """Trajectories -> segment -> (fine-tune the object-VAE) -> two LSTMs -> retrieval."""
    import time

    import envs_mjx
    from roll_jax.segmentation import pipeline

    t0 = time.perf_counter()
    cfg, pre, seg = load_checkpoint(ckpt, task, preset)
    if pre.object_vae is None:
        raise ValueError("the occlusion analysis needs a checkpoint with an object-VAE")
    env = envs_mjx.make(task)
    horizon = horizon or env.horizon
    key = jax.random.PRNGKey(seed)
    k_path, k_vae, k_lstm, k_occ = jax.random.split(key, 4)
    puck, hand = puck_paths(k_path, task, n_train + n_eval, horizon)
    rgb = render_pushes(env, puck, hand)
    seg_fn = functools.partial(jax.jit(pipeline.segment), seg)  # params as arguments
    masks = batched(seg_fn, rgb.reshape((-1,) + rgb.shape[2:]), 256).reshape(rgb.shape[:-1])
    images = np.where(masks[..., None], rgb, 0).astype(np.uint8)
    t_data = time.perf_counter() - t0
    tr, ev = slice(0, n_train), slice(n_train, n_train + n_eval)
    vcfg = cfg.object_vae
    vae_state, vae_hist = finetune_vae(k_vae, pre.object_vae, vcfg,
                                       images[tr].reshape((-1, 48, 48, 3)),
                                       masks[tr].reshape((-1, 48, 48)), vae_steps)
    curve_steps = [s for s in CURVE_STEPS if s < lstm_steps] + [lstm_steps]
    _, lstm_hist, snaps = train_occlusion_lstms(
        k_lstm, vae_state.params, vcfg, cfg.lstm, images[tr], masks[tr], lstm_steps, batch,
        snapshot_steps=curve_steps)  # snaps[lstm_steps]: the final weights
    t_train = time.perf_counter() - t0 - t_data
    frame_encoder, _ = occlusion_models(vae_state.params, vcfg, {})
    queries = occlusion_queries(k_occ, images[ev], masks[ev], frame_encoder, drop,
                                min_t=cfg.lstm.min_occlusion_t)
    lat, _, occ_t = queries
    curve = []
    for step in curve_steps:
        heads = occlusion_models(vae_state.params, vcfg, snaps[step])[1]
        res = score_heads(*queries, puck[ev], heads)
        # The paper's pool holds the query's own clean trajectory, whose LSTM codes share
        # the query's history; retrieving from the other trajectories only checks that the
        # codes locate the puck rather than the trajectory.
        others = score_heads(*queries, puck[ev], heads, exclude_own=True)
        # The same frames unoccluded, from the other trajectories: how well each code
        # locates the puck it is shown, the baseline of the occluded frames' errors.
        clean = score_heads(lat, lat, occ_t, puck[ev], heads, exclude_own=True)
        curve.append(curve_row(step, res, lstm_hist, others, clean))
    # res, others and clean are now the final weights' (curve_steps ends at lstm_steps).
    seg_px = masks.reshape(masks.shape[0], masks.shape[1], -1).sum(-1)
    extra = {"preset": cfg.preset, "ckpt": os.path.abspath(ckpt), "seed": seed,
             "n_train_trajectories": n_train, "n_eval_trajectories": n_eval, "horizon": horizon,
             "drop": drop, "train_drop": cfg.lstm.occlusion_drop, "lstm_steps": lstm_steps,
             "lstm_batch": batch, "vae_steps": vae_steps,
             "segmented_pixels_mean": float(seg_px.mean()),
             "frames_without_object_pixels": float((seg_px == 0).mean()),
             "loss_first_last": {"vae": _first_last(vae_hist),
                                 **{k: _first_last(v) for k, v in lstm_hist.items()}},
             "seconds": {"data": round(t_data, 1), "train": round(t_train, 1)},
             "error_cm_other_trajectories": others["error_cm"],
             "median_cm_other_trajectories": others["median_cm"],
             "error_cm_clean_frames": clean["error_cm"],
             "ordering_holds": curve[-1]["ordering_holds"],
             "ordering_holds_at_steps": [c["lstm_steps"] for c in curve if c["ordering_holds"]],
             "curve": curve}
    png, js = write_occlusion(res, out, task, extra)
    curve_png = write_occlusion_curve(curve, out, task)
    return {"task": task, "error_cm": res["error_cm"], "png": png, "curve_png": curve_png,
            "json": js, **extra}


def _first_last(h) -> list | None:
    h = np.asarray(h)
    return [float(h[0]), float(h[-1])] if h.size else None


def main(argv=None):
    from configs.train import PRESETS, TASKS

    p = argparse.ArgumentParser(prog="python -m roll_jax.analysis", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="cmd", required=True)
    a1 = sub.add_parser("latent-vs-distance", help="paper Figure 5")
    a1.add_argument("--task", required=True, choices=TASKS)
    a1.add_argument("--n", type=int, default=500, help="observations (default 500)")
    a2 = sub.add_parser("occlusion", help="appendix A occlusion retrieval")
    a2.add_argument("--task", default="hurdle_top", choices=HURDLE_TASKS)
    a2.add_argument("--n-train", type=int, default=None,
                    help="training trajectories (default: the preset's, configs/presets.py)")
    a2.add_argument("--n-eval", type=int, default=None,
                    help="evaluation trajectories = queries (default: the preset's)")
    a2.add_argument("--horizon", type=int, default=None, help="frames per trajectory (task's)")
    a2.add_argument("--lstm-steps", type=int, default=None,
                    help="steps per LSTM (default: the preset's)")
    a2.add_argument("--vae-steps", type=int, default=None,
                    help="object-VAE fine-tuning steps on the trajectories (default: the "
                         "preset's)")
    a2.add_argument("--batch", type=int, default=25, help="LSTM batch (trajectories), default 25")
    a2.add_argument("--drop", type=float, default=OCCLUSION_DROP)
    for a in (a1, a2):
        a.add_argument("--ckpt", required=True, help="python -m roll_jax.pretrain --out DIR")
        a.add_argument("--out", default=None, help="default: CKPT/analysis")
        a.add_argument("--preset", default=None, choices=PRESETS,
                       help="default: the checkpoint's (pretrain.json)")
        a.add_argument("--seed", type=int, default=0)
    a = p.parse_args(argv)
    out = a.out or os.path.join(a.ckpt, "analysis")
    try:
        if a.cmd == "latent-vs-distance":
            res = run_latent_vs_distance(a.task, a.ckpt, out, a.n, a.seed, a.preset)
        else:
            from configs import presets

            d = presets.get(checkpoint_preset(a.ckpt, a.task, a.preset)).for_task(
                "occlusion", a.task)
            res = run_occlusion(a.ckpt, out, a.task,
                                n_train=a.n_train or d["n_train"], n_eval=a.n_eval or d["n_eval"],
                                horizon=a.horizon,
                                lstm_steps=d["lstm_steps"] if a.lstm_steps is None else a.lstm_steps,
                                vae_steps=d["vae_steps"] if a.vae_steps is None else a.vae_steps,
                                batch=a.batch, drop=a.drop, seed=a.seed, preset=a.preset)
    except (FileNotFoundError, ValueError) as e:
        sys.exit(f"error: {e}")
    print(json.dumps(res, indent=2))


if __name__ == "__main__":
    main()
