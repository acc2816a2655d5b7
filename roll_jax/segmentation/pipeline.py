"""Unknown-object segmentation: background model + robot U-Net -> object mask.

Paper section "Unknown Object Segmentation" and appendix B.1:

1. random actions in the object-free scene (`env.empty_scene()`) give `n_frames` images;
   MOG2 is fitted on them with history = n_frames and OpenCV's automatic learning rate;
2. the frozen MOG2's foreground on those same frames labels the robot (with its background
   ratio set to `cfg.label_background_ratio`: a mask-only setting, the fitted modes are the
   same);
3. a U-Net learns robot-vs-rest from those labels, with synthetic object-like distractors
   pasted in and labelled not-robot (otherwise anything that moves would be "robot");
4. `segment(params, rgb)`: object mask = MOG2 foreground (lr 0, shadows count) AND NOT
   robot (U-Net probability > threshold); segmented image = rgb * mask.

The algorithm never reads ground-truth labels; `evaluate` uses them to score the masks.
"""

from __future__ import annotations

import dataclasses
import functools
import os

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from configs.segmentation import SegmentationConfig
from roll_jax.common.checkpoint import read_meta, write_meta
from roll_jax.segmentation import mog2, unet

CHECKPOINT_VERSION = 1


@struct.dataclass
class SegParams:
    """Everything `segment` needs; a pytree, so it lives inside the training state."""

    background: mog2.MOG2Model  # frozen after fitting
    unet: unet.UNetState
    robot_threshold: jax.Array  # float32 scalar


# ----------------------------------------------------------------------------- data

def record_empty_scene(env, key, n_frames: int, n_envs: int, width: int = 48,
                       height: int = 48) -> jax.Array:
    """uint8[n_frames, H, W, 3] of the robot moving at random in the object-free scene.

    `n_envs` random walks run side by side, each starting from a random hand position in the
    task's hand box; frames are interleaved in time (env 0 step 0, env 1 step 0, ...), which
    MOG2, a per-pixel statistic, does not mind.
    """
    steps = -(-n_frames // n_envs)
    rgb = _empty_walks_fn(env.empty_scene(), steps, width, height)(
        jax.random.split(key, n_envs))  # [E, T, H, W, 3]
    rgb = jnp.swapaxes(rgb, 0, 1).reshape((-1,) + rgb.shape[2:])
    return rgb[:n_frames]


@functools.lru_cache(maxsize=None)
def _empty_walks_fn(empty, steps: int, width: int, height: int):
    """jit(vmap) of one rendered random walk in the object-free scene, built once per env."""
    from envs_mjx.rollout import random_actions, rollout

    def one(k):
        k_hand, k_act = jax.random.split(k)
        state = empty.place(empty.random_hand(k_hand))
        _, traj = rollout(empty, state, random_actions(k_act, steps, empty.action_size),
                          render=True, width=width, height=height)
        return traj.rgb

    return jax.jit(jax.vmap(one))


def fit_background(frames, cfg: SegmentationConfig) -> mog2.MOG2Model:
    """MOG2 with history = number of frames, automatic learning rate (appendix B.1)."""
    frames = jnp.asarray(frames)
    h, w, c = frames.shape[1:]
    model = mog2.init(h, w, c, history=frames.shape[0], var_threshold=cfg.var_threshold,
                      detect_shadows=cfg.detect_shadows, n_mixtures=cfg.n_mixtures)
    model, _ = mog2.apply_video(model, frames, learning_rate=-1.0)
    return model


def robot_labels(background: mog2.MOG2Model, frames, background_ratio: float) -> jax.Array:
    """bool[N, H, W]: the fitted model's foreground on `frames`, classified with
    `background_ratio` (a mask-only setting: OpenCV uses it for no model update)."""
    labeller = background.replace(background_ratio=np.float32(background_ratio))
    return mog2.foreground(labeller, frames, shadows_as_foreground=True)


def paste_distractors(key, images, labels, prob: float, near_robot: float = 0.0,
                      max_radius: float = 8.0, behind_robot: float = 0.0):
    """Paste one object-like blob (ellipse or box, random size and colour) into each image with
    probability `prob`; its pixels become not-robot. With probability `near_robot` the blob is
    centred on a robot-labelled pixel (the object touching the arm, as when the hand holds the
    door or the ball), otherwise anywhere. With probability `behind_robot` the blob lies behind
    the arm: it is painted only on not-robot pixels, so the arm keeps its labels and is seen in
    front of a new colour (the gripper in front of the door). Radii are 1.5..`max_radius` px at
    48x48. Pure and jittable (per minibatch)."""
    n, h, w, _ = images.shape
    ks = jax.random.split(key, 9)
    use = jax.random.uniform(ks[0], (n,)) < prob
    scale = min(h, w) / 48.0  # sizes below are for 48x48 images
    cy = jax.random.uniform(ks[1], (n,), minval=0, maxval=h)
    cx = jax.random.uniform(ks[2], (n,), minval=0, maxval=w)
    robot = labels.reshape(n, -1) > 0.5
    pick = jax.random.categorical(ks[6], jnp.where(robot, 0.0, -jnp.inf))  # a robot pixel
    on_robot = (jax.random.uniform(ks[7], (n,)) < near_robot) & robot.any(-1)
    cy = jnp.where(on_robot, (pick // w).astype(jnp.float32) + 0.5, cy)
    cx = jnp.where(on_robot, (pick % w).astype(jnp.float32) + 0.5, cx)
    radii = jax.random.uniform(ks[3], (n, 2), minval=1.5 * scale, maxval=max_radius * scale)
    colour = jax.random.randint(ks[4], (n, 3), 0, 256).astype(jnp.uint8)
    is_box = jax.random.bernoulli(ks[5], 0.5, (n,))
    yy, xx = jnp.mgrid[0:h, 0:w]
    dy = (yy[None] + 0.5 - cy[:, None, None]) / radii[:, 0, None, None]
    dx = (xx[None] + 0.5 - cx[:, None, None]) / radii[:, 1, None, None]
    ellipse = dy ** 2 + dx ** 2 <= 1.0
    box = (jnp.abs(dy) <= 1.0) & (jnp.abs(dx) <= 1.0)
    blob = jnp.where(is_box[:, None, None], box, ellipse) & use[:, None, None]
    behind = jax.random.uniform(ks[8], (n,)) < behind_robot
    blob = blob & ~(behind[:, None, None] & (labels > 0.5))
    images = jnp.where(blob[..., None], colour[:, None, None, :], images)
    labels = jnp.where(blob, jnp.zeros_like(labels), labels)
    return images, labels


# ----------------------------------------------------------------------------- fitting

@functools.lru_cache(maxsize=None)
def _distractors(cfg: SegmentationConfig):
    """The config's distractor pasting, one function per config (the U-Net's compiled epoch
    is cached per augmentation function)."""
    return functools.partial(paste_distractors, prob=cfg.distractor_prob,
                             near_robot=cfg.distractor_near_robot,
                             max_radius=cfg.distractor_max_radius,
                             behind_robot=cfg.distractor_behind_robot)


def fit(env, key, cfg: SegmentationConfig, progress=None, frames=None):
    """Fit the background model and the robot U-Net for `env`'s task.

    Returns (SegParams, info) where info holds the recorded frames, robot labels and the
    U-Net's loss history (for figures and tests)."""
    k_rec, k_unet = jax.random.split(key)
    if frames is None:
        frames = record_empty_scene(env, k_rec, cfg.n_frames, cfg.n_envs)
    background = fit_background(frames, cfg)
    robot = robot_labels(background, frames, cfg.label_background_ratio)
    state, history = unet.fit_unet(k_unet, frames, robot.astype(jnp.float32), cfg,
                                   augment_fn=_distractors(cfg), progress=progress)
    params = SegParams(background=background, unet=state,
                       robot_threshold=jnp.float32(cfg.robot_threshold))
    return params, {"frames": frames, "robot_labels": robot, "unet_loss": history}


# ----------------------------------------------------------------------------- segment

def _check_rgb(params: SegParams, rgb) -> None:
    shape = tuple(params.background.image_shape)
    got_shape = tuple(getattr(rgb, "shape", ()))
    dtype = getattr(rgb, "dtype", None)
    if got_shape[-3:] != shape or dtype != jnp.uint8:
        raise ValueError(f"segment: expected uint8 images [..., {shape[0]}, {shape[1]}, "
                         f"{shape[2]}], got {dtype} {list(got_shape)}")


def masks(params: SegParams, rgb):
    """(foreground, robot, object) bool masks [..., H, W] for uint8 rgb [..., H, W, 3]."""
    lead, img = rgb.shape[:-3], rgb.shape[-3:]
    flat = rgb.reshape((-1,) + img)
    fg = mog2.frozen_foreground(params.background, flat)
    robot = unet.robot_probability(params.unet, flat) > params.robot_threshold
    obj = fg & ~robot
    return tuple(m.reshape(lead + img[:2]) for m in (fg, robot, obj))


def segment(params: SegParams, rgb):
    """Object mask bool[..., H, W] of uint8 rgb [..., H, W, 3]; pure and jittable."""
    _check_rgb(params, rgb)  # static shape/dtype: works on tracers too
    return masks(params, rgb)[2]


def segmented_image(rgb, mask):
    """rgb * mask: the object on black (the object-VAE's input)."""
    return jnp.where(mask[..., None], rgb, jnp.zeros_like(rgb))


# ----------------------------------------------------------------------------- evaluation

@functools.lru_cache(maxsize=None)
def _object_states_fn(env, settle_steps: int, arm_pairs: bool = False, hand: str = "random"):
    """jit(vmap) of one random object state, built once per env and settings: a fresh
    closure per call would trace and compile the MJX rollout and the renderer again."""
    from envs_mjx.rollout import random_actions, rollout

    def one(k):
        k_h, k_o, k_a = jax.random.split(k, 3)
        state = env.away_placement(k_o) if hand == "away" else env.random_placement(k_h, k_o)
        if settle_steps:  # (0: kinematics only, no MJX step in the compiled program)
            state, _ = rollout(env, state, random_actions(k_a, settle_steps, env.action_size))
        if not arm_pairs:
            return env.render_both(state)
        # The same object state with the hand at another random place (kinematic placement).
        other = env.place(env.random_hand(jax.random.fold_in(k, 1)), env.object_state(state))
        return (*env.render_both(state), *env.render_both(other))

    return jax.jit(jax.vmap(one))


def random_object_states(env, key, n: int, settle_steps: int = 5, chunk: int = 32,
                         arm_pairs: bool = False, hand: str = "random"):
    """States with the hand uniform in its box (`hand="away"`: out of view) and the object
    where it can be (`env.random_placement`), after a few random steps so the scene settles;
    returns numpy (rgb, labels) [n, H, W, ...].
    `arm_pairs`: (rgb, labels, rgb_b, labels_b), the second pair the same object states
    rendered with the hand at another random place. State i depends only on `key` and i (not
    on `chunk`), and its first rendering not on `arm_pairs`."""
    # Fixed chunks of `chunk` states, one compile: a single vmap over ~750 pickup states sat
    # asleep on a futex for hours on CPU (twice), while chunks of 16-32 run in < 1 s each.
    keys = jax.random.split(key, n)
    pad = -n % chunk
    keys = jnp.take(keys, jnp.arange(n + pad) % n, axis=0)  # whole chunks, n < chunk too
    if hand not in ("random", "away"):
        raise ValueError(f"hand must be 'random' or 'away', got {hand!r}")
    run = _object_states_fn(env, settle_steps, arm_pairs, hand)
    outs = [jax.device_get(run(keys[i:i + chunk])) for i in range(0, n + pad, chunk)]
    return tuple(np.concatenate(parts)[:n] for parts in zip(*outs))


def mask_scores(pred, labels):
    """Per-image IoU with labels == 2, robot leakage (share of robot pixels kept) and
    background leakage (share of background pixels kept)."""
    obj, robot, bg = labels == 2, labels == 1, labels == 0
    axes = (-2, -1)

    def frac(a, b):
        return (a & b).sum(axes) / jnp.maximum(b.sum(axes), 1)

    iou = (pred & obj).sum(axes) / jnp.maximum((pred | obj).sum(axes), 1)
    return {"iou": iou, "robot_leakage": frac(pred, robot), "background_leakage": frac(pred, bg)}


THRESHOLD_SWEEP = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7)


def _summary(obj, labels) -> tuple[dict, dict]:
    scores = {k: np.asarray(v) for k, v in mask_scores(jnp.asarray(obj), jnp.asarray(labels)).items()}
    has_robot = (labels == 1).sum((-2, -1)) > 0
    pooled = float((obj & (labels == 2)).sum() / max((obj | (labels == 2)).sum(), 1))
    summary = {"iou": float(scores["iou"].mean()), "iou_median": float(np.median(scores["iou"])),
               "iou_pooled": pooled,
               "robot_leakage": float(scores["robot_leakage"][has_robot].mean()),
               "background_leakage": float(scores["background_leakage"].mean())}
    return summary, scores


@jax.jit
def _probabilities(params: SegParams, rgb):
    """(MOG2 foreground, U-Net robot probability) of each image."""
    return mog2.frozen_foreground(params.background, rgb), unet.robot_probability(params.unet, rgb)


def evaluate(env, params: SegParams, key, n_states: int) -> tuple[dict, dict]:
    """`score` over `n_states` random states whose object is visible; (summary, arrays)."""
    rgb, labels = random_object_states(env, key, int(n_states * 1.5) + 8)
    rgb, labels = np.asarray(rgb), np.asarray(labels)
    visible = (labels == 2).sum((-2, -1)) > 0
    summary, arrays = score(params, rgb[visible][:n_states], labels[visible][:n_states])
    return {"task": env.name, **summary}, arrays


def score(params: SegParams, rgb, labels) -> tuple[dict, dict]:
    """The masks of uint8 images rgb [n, H, W, 3] against their labels [n, H, W]; (summary,
    arrays). The summary is for the params' robot threshold; `threshold_sweep` repeats the
    scores for other thresholds (same U-Net probabilities), the data for choosing a task's
    threshold."""
    rgb, labels = np.asarray(rgb), np.asarray(labels)
    fg, prob = (np.asarray(a) for a in _probabilities(params, jnp.asarray(rgb)))
    robot = prob > float(params.robot_threshold)
    obj = fg & ~robot
    summary, scores = _summary(obj, labels)
    summary = {"n_states": len(rgb), "robot_threshold": float(params.robot_threshold), **summary,
               "object_pixels_mean": float((labels == 2).sum((-2, -1)).mean()),
               "threshold_sweep": {f"{t:.1f}": _summary(fg & ~(prob > t), labels)[0]
                                   for t in THRESHOLD_SWEEP}}
    arrays = {"rgb": rgb, "labels": labels, "foreground": fg, "robot": robot, "object": obj,
              **scores}
    return summary, arrays


def figure2(arrays: dict, path: str, n: int = 4) -> None:
    """The paper's Figure 2 panel for `n` states: original, foreground, robot mask, object
    mask, segmented object."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    titles = ("original", "foreground", "robot mask", "object mask", "segmented object")
    n = min(n, len(arrays["rgb"]))
    fig, axes = plt.subplots(n, 5, figsize=(7.5, 1.6 * n), squeeze=False)
    for i in range(n):
        rgb = arrays["rgb"][i]
        seg = np.where(arrays["object"][i][..., None], rgb, 0)
        panels = (rgb, arrays["foreground"][i], arrays["robot"][i], arrays["object"][i], seg)
        for j, img in enumerate(panels):
            ax = axes[i, j]
            ax.imshow(img, cmap="gray", vmin=0, vmax=1, interpolation="nearest")
            ax.set_xticks([])
            ax.set_yticks([])
            if i == 0:
                ax.set_title(titles[j], fontsize=8)
        axes[i, 0].set_ylabel(f"IoU {arrays['iou'][i]:.2f}", fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


# ----------------------------------------------------------------------------- checkpoints

def _meta(task: str, params: SegParams, cfg: SegmentationConfig) -> dict:
    h, w, c = params.background.image_shape
    return {"version": CHECKPOINT_VERSION, "task": task, "image_shape": [h, w, c],
                "unet_features": cfg.unet_features, "config": dataclasses.asdict(cfg)}


def save(path: str, task: str, params: SegParams, cfg: SegmentationConfig) -> None:
    """Orbax checkpoint of the params plus a meta.json naming task and image size."""
    import orbax.checkpoint as ocp

    path = write_meta(path, _meta(task, params, cfg))
    with ocp.StandardCheckpointer() as ckptr:
        ckptr.save(os.path.join(path, "params"), params, force=True)


def load(path: str, task: str, image_shape=(48, 48, 3)) -> tuple[SegParams, SegmentationConfig]:
    """Restore a checkpoint; refuses one fitted for another task or image size."""
    import orbax.checkpoint as ocp

    path, meta = read_meta(path, "segmentation")
    if meta["task"] != task:
        raise ValueError(f"segmentation checkpoint {path} was fitted for task "
                         f"{meta['task']!r}, not {task!r}")
    if tuple(meta["image_shape"]) != tuple(image_shape):
        raise ValueError(f"segmentation checkpoint {path} is for images {meta['image_shape']}, "
                         f"not {list(image_shape)}")
    cfg = SegmentationConfig(**meta["config"])
    h, w, c = image_shape
    target = jax.eval_shape(lambda: initial_params(h, w, c, cfg))
    with ocp.StandardCheckpointer() as ckptr:
        params = ckptr.restore(os.path.join(path, "params"), target)
    return params, cfg


def initial_params(h: int, w: int, c: int, cfg: SegmentationConfig,
                   key=None) -> SegParams:
    """Unfitted params of the config's shape: an empty background model (every pixel is
    foreground) and a freshly initialised U-Net."""
    background = mog2.init(h, w, c, history=cfg.n_frames, var_threshold=cfg.var_threshold,
                           detect_shadows=cfg.detect_shadows, n_mixtures=cfg.n_mixtures)
    state = unet.init_unet(jax.random.PRNGKey(0) if key is None else key, cfg.unet_features, h, w)
    return SegParams(background=background, unet=state,
                     robot_threshold=jnp.float32(cfg.robot_threshold))
