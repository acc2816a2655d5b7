"""Figure 5, "segmented images give a better reward": for N observations and one goal, the
true object distance against the scene-VAE latent distance and the object latent distance
(object-VAE of the segmented image, then one LSTM step from the zero state, the way a goal
image is encoded), with the Spearman rank correlation of each; and how well the latents
locate the object (`stats`), beside what the observations allow (`pixel_reference`,
`known_reference`).

    python -m roll_jax.analysis latent-vs-distance --task TASK --ckpt DIR [--out DIR]

The core functions take encoders as plain callables (images -> latents), so tests can feed
synthetic images and ideal encoders; `checkpoints.model_encoders` builds them from a
checkpoint.
"""

from __future__ import annotations

import dataclasses
import json
import os
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np

from roll_jax.analysis.checkpoints import batched, frame_encode, load_checkpoint, model_encoders
from roll_jax.analysis.stats import (
    finite_or_none,
    pairwise_spearman,
    pearson,
    position_r2,
    position_r2_nonlinear,
    rounded_list,
    spearman,
)
from roll_jax.encoders.goal_encoding import Frozen, goal_encoder
from roll_jax.segmentation import pipeline


def _units(env) -> tuple[str, float]:
    """Axis label and scale for the task's object distance."""
    if env.kind == "door":
        return "door angle distance (rad)", 1.0
    return "object distance (cm)", 100.0


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


# The nearest fifth of the observations to the goal, by the object's distance: Fig. 5's
# near-goal Spearman (a 0.90 overall on the door hid 0.25 within 0.1 rad of the goal).
NEAR_GOAL_SHARE = 0.2


def near_goal(distances) -> np.ndarray:
    """[n] bool: the observations among the nearest NEAR_GOAL_SHARE to the goal."""
    distances = np.asarray(distances, np.float64)
    return distances <= np.quantile(distances, NEAR_GOAL_SHARE)


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
    near = near_goal(obs.distances)
    return {"reference_spearman_object": spearman(obs.distances, d),
            "reference_near_goal_spearman_object": spearman(obs.distances[near], d[near]),
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
    # The policy's last stretch: can the reward tell nearly there from there?
    near = near_goal(distances)
    return {
        "n": int(distances.size),
        "spearman_object": spearman(distances, obj),
        "spearman_scene": spearman(distances, scene),
        "near_goal_distance": float(distances[near].max()),
        "near_goal_spearman_object": spearman(distances[near], obj[near]),
        "near_goal_spearman_scene": spearman(distances[near], scene[near]),
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
               "spearman_object": finite_or_none(result["spearman_object"]),
               "spearman_scene": finite_or_none(result["spearman_scene"]),
               "pearson_object": finite_or_none(result["pearson_object"]),
               "pearson_scene": finite_or_none(result["pearson_scene"]),
               "near_goal_distance": result["near_goal_distance"],
               "near_goal_spearman_object": finite_or_none(result["near_goal_spearman_object"]),
               "near_goal_spearman_scene": finite_or_none(result["near_goal_spearman_scene"]),
               **(extra or {}),
               "object_distance": rounded_list(result["object_distance"]),
               "object_latent_distance": rounded_list(result["object_latent_distance"]),
               "scene_latent_distance": rounded_list(result["scene_latent_distance"])}
    with open(js, "w") as f:
        json.dump(summary, f, indent=1)
    return png, js


def goal_mask_scores(seg, obs: ObservationSet) -> dict:
    """How the segmentation masks the goal image, against the renderer's labels: every
    observation is compared with that one code, so a goal whose object is half masked away
    (pickup's cube held in the gripper) misplaces the whole ranking."""
    labels = jnp.asarray(obs.goal_labels)[None]
    scores = pipeline.mask_scores(pipeline.segment(seg, jnp.asarray(obs.goal_rgb)[None]), labels)
    return {"goal_object_pixels": int((obs.goal_labels == 2).sum()),
            "goal_mask_iou": round(float(scores["iou"][0]), 4),
            "goal_mask_robot_leakage": round(float(scores["robot_leakage"][0]), 4)}


def run_latent_vs_distance(task: str, ckpt: str, out: str, n: int = 500, seed: int = 0,
                           preset: str | None = None) -> dict:
    import envs_mjx

    cfg, pre, seg = load_checkpoint(ckpt, task, preset)
    if pre.object_vae is None:
        raise ValueError(f"{ckpt}: Figure 5 needs encoders with an object-VAE (ROLL's); this "
                         f"{cfg.algo} checkpoint has none")
    env = envs_mjx.make(task)
    obs_set = observation_set(env, jax.random.PRNGKey(seed), n)
    obs, goal, dist, pos = obs_set.rgb, obs_set.goal_rgb, obs_set.distances, obs_set.states
    encode_scene, encode_object = model_encoders(cfg, pre, seg)
    res = latent_vs_distance(obs, goal, dist, encode_scene, encode_object)
    # The object-VAE itself, on these held-out segmented images: its means against the
    # object's state (position; door: angle).
    enc = goal_encoder(cfg)
    frozen = Frozen(seg=seg, object_vae=pre.object_vae.params)
    means = batched(lambda x: frame_encode(enc, frozen, pre.scene_vae.params, x), obs, 512)
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
    summary = {k: res[k] for k in ("n", "spearman_object", "spearman_scene", "near_goal_distance",
                                   "near_goal_spearman_object", "near_goal_spearman_scene")}
    return {**summary, **probe, "task": task, "png": png, "json": js}
