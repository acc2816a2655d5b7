"""Pre-training of the scene-VAE, the object-VAE and the LSTM (Algorithm 1, first lines;
appendix "Training schedules").

    python -m roll_jax.encoders.pretrain --task TASK [--preset smoke|cpu|paper] --out DIR [--seg DIR]
        [--set object_vae.occlusion_shape=edge ...]        (roll-pretrain; encoders/cli.py)

- scene data: `n_pretrain_images` frames of a random policy (whole episodes from resets), or
  of states set to random goals (TrainConfig.scene_pretrain_data, per task);
- object data: as many frames with the object (and the hand) placed at random, segmented
  with `segment` (never with ground-truth labels);
- scene-VAE: beta-VAE loss; object-VAE: + the VAE matching loss; LSTM: auto-encoder loss on
  sequences of object-VAE latents drawn from the object data (the paper pre-trains it "on the
  same dataset"; the frames are independent placements, so a sequence is a random draw of
  `horizon` of them);
- one jitted epoch function per model (a lax.scan over its batches), orbax checkpoints,
  a progress bar, reconstruction grids as PNG.
"""

from __future__ import annotations

if __name__ == "__main__":  # the command parses its arguments before JAX loads (encoders/cli.py)
    import sys

    from roll_jax.encoders.cli import main

    sys.exit(main())

import dataclasses
import functools
import hashlib
import json
import os
import sys

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from configs.train import TrainConfig
from roll_jax.common.checkpoint import read_meta, write_meta
from roll_jax.encoders import models, steps
from roll_jax.encoders.goal_encoding import goal_encoder
from roll_jax.segmentation import pipeline

# 3: the push tasks' hand boxes, resets and pretraining placements are the reference code's
# (envs_mjx/tasks.py); encoders of version 2 saw the earlier task numbers and are refused on
# load. (Version 1 weighed the KL by beta per image, a collapsed object-VAE.)
CHECKPOINT_VERSION = 3


@struct.dataclass
class Pretrained:
    scene_vae: steps.ModelState
    object_vae: steps.ModelState | None
    lstm: steps.ModelState | None


def scene_dataset(env, key, n_images: int, source: str = "random_policy") -> jax.Array:
    """uint8 [n, 48, 48, 3]: "random_policy", frames of random-policy episodes from resets
    (after each step; the paper's text); "goals", states set to goals drawn from the task's
    goal space (`env.sample_goal`: hand and object placed), rlkit's
    `oracle_dataset_using_set_to_goal` that the reference code's puck_push launch file uses;
    "region", hand and object each placed over where the object can be (`env.region_placement`:
    the reference's hurdle corridor sampler); "placements", the hand uniform in its box and the
    object where it can be (`env.random_placement`) (TrainConfig.scene_pretrain_data)."""
    if source == "goals":
        return _goal_images_fn(env)(jax.random.split(key, n_images))
    if source in ("region", "placements"):
        placement = "region_placement" if source == "region" else "random_placement"
        return _placement_images_fn(env, placement)(jax.random.split(key, n_images))
    if source != "random_policy":
        raise ValueError(f"scene data source must be 'random_policy', 'goals', 'region' or "
                         f"'placements', got {source!r}")
    n_eps = -(-n_images // env.horizon)
    rgb = _random_episodes_fn(env)(jax.random.split(key, n_eps))
    return rgb.reshape((-1,) + rgb.shape[2:])[:n_images]


# Built once per env: a fresh closure per call would trace and compile MJX and the renderer
# again for every run in the process.
@functools.lru_cache(maxsize=None)
def _goal_images_fn(env):
    return jax.jit(jax.vmap(lambda k: env.render(env.sample_goal(k))))


@functools.lru_cache(maxsize=None)
def _placement_images_fn(env, placement: str):
    """Renders of `env.<placement>(k_hand, k_object)` (region_placement, random_placement)."""
    place = getattr(env, placement)
    return jax.jit(jax.vmap(lambda k: env.render(place(*jax.random.split(k)))))


@functools.lru_cache(maxsize=None)
def _random_episodes_fn(env):
    from envs_mjx.rollout import random_actions, rollout

    def one(k):
        k_r, k_a = jax.random.split(k)
        _, traj = rollout(env, env.reset(k_r), random_actions(k_a, env.horizon, env.action_size),
                          render=True)
        return traj.rgb

    return jax.jit(jax.vmap(one))


def object_dataset(env, seg_params, key, n_images: int, goal_share: float = 0.0,
                   arm_pairs: bool = False, hand: str = "random"):
    """(segmented images uint8 [n, 48, 48, 3], object masks bool [n, 48, 48]) of random object
    placements, masks from `segment`; the first round(goal_share * n) are states set to goals
    (`env.sample_goal`) instead. The placements are taken as placed (like the goal images),
    not settled by a few physics steps: that keeps MJX's step, the slowest program to compile,
    out of this one. `hand`: "random" (uniform in its box) or "away" (out of view). `arm_pairs`: also the partners (images, masks) of `VAEConfig.arm_pair_coef`,
    each image's object state with the hand at another random place; a goal image is its own
    partner. The first two arrays do not depend on `arm_pairs`."""
    if not 0.0 <= goal_share <= 1.0:
        raise ValueError(f"goal_share must be in [0, 1], got {goal_share!r}")
    n_goals = int(round(goal_share * n_images))
    k_place, k_goal = jax.random.split(key) if n_goals else (key, None)
    parts, partners = [], []
    if n_goals:
        goals = np.asarray(_goal_images_fn(env)(jax.random.split(k_goal, n_goals)))
        parts.append(goals)
        partners.append(goals)
    if n_images > n_goals:
        placed = pipeline.random_object_states(env, k_place, n_images - n_goals,
                                               settle_steps=0, arm_pairs=arm_pairs,
                                               hand=hand)
        parts.append(placed[0])
        if arm_pairs:
            partners.append(placed[2])
    segment = jax.jit(pipeline.segment)
    rgb = np.concatenate(parts)
    masks = segment(seg_params, rgb)
    out = (pipeline.segmented_image(rgb, masks), masks)
    if not arm_pairs:
        return out
    rgb_b = np.concatenate(partners)
    masks_b = segment(seg_params, rgb_b)
    return out + (pipeline.segmented_image(rgb_b, masks_b), masks_b)


def occlude_share(key, images, masks, fraction: float, drop: float):
    """The reference code's occluded pre-training images: each image is, with probability
    `fraction`, stored with every pixel dropped with probability `drop` (one mask per image).
    images uint8 [n, H, W, 3], masks bool [n, H, W] -> the same, masks reduced to the object
    pixels left."""
    k_pick, k_pix = jax.random.split(key)
    picked = jax.random.bernoulli(k_pick, fraction, images.shape[:1])
    dropped = jax.random.bernoulli(k_pix, drop, masks.shape) & picked[:, None, None]
    return jnp.where(dropped[..., None], jnp.zeros_like(images), images), masks & ~dropped


def _fit_vae(key, cfg, data, masks, desc, progress: bool, partners=None):
    from tqdm import tqdm

    state = steps.init_vae(key, cfg)
    epoch = jax.jit(steps.vae_fit_epoch, static_argnames="cfg")
    losses = []
    bar = tqdm(range(cfg.epochs), desc=desc, unit="epoch", disable=not progress)
    for e in bar:
        state, m = epoch(state, jax.random.fold_in(key, e + 1), data, cfg, masks, partners)
        losses.append(float(m["loss"].mean()))
        if not np.isfinite(losses[-1]):
            raise FloatingPointError(f"{desc}: loss is {losses[-1]} at epoch {e}")
        bar.set_postfix(loss=f"{losses[-1]:.2f}")
    return state, losses


def _fit_lstm(key, cfg, in_dim, latents, horizon, desc, progress: bool):
    from tqdm import tqdm

    state = steps.init_lstm(key, cfg, in_dim)
    epoch = jax.jit(steps.lstm_fit_epoch, static_argnames=("cfg", "batches"))
    n = latents.shape[0]
    losses = []
    bar = tqdm(range(cfg.epochs), desc=desc, unit="epoch", disable=not progress)
    for e in bar:
        k_seq, k_ep = jax.random.split(jax.random.fold_in(key, e + 1))
        # A fresh set of random sequences each epoch (enough for the epoch's batches).
        idx = jax.random.randint(k_seq, (cfg.batch_size * 4, horizon), 0, n)
        state, m = epoch(state, k_ep, latents[idx], cfg)
        losses.append(float(m["loss"].mean()))
        if not np.isfinite(losses[-1]):
            raise FloatingPointError(f"{desc}: loss is {losses[-1]} at epoch {e}")
        bar.set_postfix(loss=f"{losses[-1]:.4f}")
    return state, losses


def _digest(tree) -> str:
    """Content hash of a pytree's arrays (identifies e.g. a fitted segmentation)."""
    h = hashlib.sha256()
    for x in jax.tree.leaves(tree):
        h.update(np.asarray(x).tobytes())
    return h.hexdigest()[:16]


def _cached(cache: str | None, name: str, spec: dict, build, like):
    """build() -> (pytree, losses). With a `cache` dir the result is stored there as
    name-HASH(spec).npz and later runs with the same spec load it instead of building it
    (the grid's runs of one task share their datasets and pre-trained models: same seed,
    same config, same bytes). `like()` gives the pytree's structure (e.g. a jax.eval_shape)
    for loading. Writes are atomic (a temp file renamed): two runs building the same entry
    at once both write the same content."""
    if cache is None:
        return build()
    text = json.dumps({"version": CHECKPOINT_VERSION, **spec}, sort_keys=True, default=str)
    path = os.path.join(cache, f"{name}-{hashlib.sha256(text.encode()).hexdigest()[:16]}.npz")
    if os.path.exists(path):
        treedef = jax.tree.structure(like())  # (traced only when loading)
        with np.load(path) as z:
            leaves = [jax.numpy.asarray(z[f"leaf_{i}"]) for i in range(treedef.num_leaves)]
            losses = z["losses"].tolist()
        return jax.tree.unflatten(treedef, leaves), losses
    tree, losses = build()
    os.makedirs(cache, exist_ok=True)
    tmp = f"{path}.tmp{os.getpid()}.npz"
    np.savez(tmp, losses=np.asarray(losses if losses is not None else [], np.float64),
             **{f"leaf_{i}": np.asarray(x) for i, x in enumerate(jax.tree.leaves(tree))})
    os.replace(tmp, path)
    with open(path[:-4] + ".json", "w") as f:  # what the entry is, for a reader of the dir
        f.write(text)
    return tree, losses


def _key(k) -> list:
    return np.asarray(k).tolist()


def pretrain(cfg: TrainConfig, env, seg_params, key, progress: bool = True,
             cache: str | None = None):
    """Returns (Pretrained, info) with datasets and loss histories for figures and tests.
    `cache`: a directory where datasets and trained models are shared between runs (see
    `_cached`; info then holds only what this call built or loaded)."""
    enc = goal_encoder(cfg)
    k_sd, k_od, k_s, k_o, k_l = jax.random.split(key, 5)
    info = {}
    n_scene = cfg.scene.n_pretrain_images
    sd_spec = {"task": cfg.task, "n": n_scene, "key": _key(k_sd),
               "source": cfg.scene_pretrain_data}
    revision = task_revision(cfg.task)
    if revision != 1:  # absent at 1: earlier caches stay valid
        sd_spec["task_revision"] = revision
    data = {}

    def scene_data():  # built or loaded once, only when a model is (re)trained on it
        if "scene" not in data:
            data["scene"], _ = _cached(
                cache, "scene_data", sd_spec,
                lambda: (scene_dataset(env, k_sd, n_scene, cfg.scene_pretrain_data), None),
                lambda: jax.ShapeDtypeStruct((n_scene,) + cfg.scene.image_shape, jax.numpy.uint8))
            info["scene_data"] = data["scene"]
        return data["scene"]

    scene_spec = {"data": sd_spec, "cfg": dataclasses.asdict(cfg.scene), "key": _key(k_s)}
    scene, info["scene_loss"] = _cached(
        cache, "scene_vae", scene_spec,
        lambda: _fit_vae(k_s, cfg.scene, scene_data(), None, "scene-VAE", progress),
        lambda: jax.eval_shape(lambda: steps.init_vae(k_s, cfg.scene)))
    obj_state = lstm_state = None
    frame_params, frame_cfg, frame_spec, frame_data = scene.params, cfg.scene, scene_spec, scene_data
    if enc.object_cfg is not None:
        ocfg, n_obj = enc.object_cfg, enc.object_cfg.n_pretrain_images
        od_spec = {"task": cfg.task, "segmentation": _digest(seg_params), "n": n_obj,
                   "key": _key(k_od), "occluded": [ocfg.pretrain_occluded_fraction,
                                                   ocfg.pretrain_occluded_drop]}
        if revision != 1:  # likewise
            od_spec["task_revision"] = revision
        if ocfg.pretrain_goal_share:  # absent at 0: earlier caches of placements stay valid
            od_spec["goal_share"] = ocfg.pretrain_goal_share
        arm_pairs = ocfg.arm_pair_coef > 0
        if arm_pairs:  # likewise
            od_spec["arm_pairs"] = True
        if ocfg.pretrain_hand != "random":  # likewise
            od_spec["hand"] = ocfg.pretrain_hand

        def build_object_data():
            arrays = object_dataset(env, seg_params, k_od, n_obj, ocfg.pretrain_goal_share,
                                    arm_pairs, ocfg.pretrain_hand)
            if ocfg.pretrain_occluded_fraction > 0:  # on each rendering, independently
                arrays = sum((occlude_share(jax.random.fold_in(k_od, 1 + i // 2),
                                            *arrays[i:i + 2], ocfg.pretrain_occluded_fraction,
                                            ocfg.pretrain_occluded_drop)
                              for i in range(0, len(arrays), 2)), ())
            return arrays, None

        def object_data():
            if "object" not in data:
                shape = (n_obj,) + ocfg.image_shape
                like = (jax.ShapeDtypeStruct(shape, jax.numpy.uint8),
                        jax.ShapeDtypeStruct(shape[:-1], jax.numpy.bool_))
                arrays, _ = _cached(cache, "object_data", od_spec, build_object_data,
                                    lambda: like * (2 if arm_pairs else 1))
                data["object"], data["masks"] = arrays[:2]
                data["partners"] = arrays[2] if arm_pairs else None
                info["object_data"] = data["object"]
            return data["object"]

        obj_spec = {"data": od_spec, "cfg": dataclasses.asdict(ocfg), "key": _key(k_o)}
        obj_state, info["object_loss"] = _cached(
            cache, "object_vae", obj_spec,
            lambda: _fit_vae(k_o, ocfg, object_data(), data["masks"], "object-VAE", progress,
                             data["partners"]),
            lambda: jax.eval_shape(lambda: steps.init_vae(k_o, ocfg)))
        frame_params, frame_cfg, frame_spec, frame_data = (obj_state.params, ocfg, obj_spec,
                                                           object_data)
    if enc.lstm:
        lcfg = cfg.lstm

        def fit_lstm():
            lat = jax.jit(models.encode_mean, static_argnames="cfg")(frame_params, frame_cfg,
                                                                        frame_data())
            return _fit_lstm(k_l, lcfg, enc.frame_dim, lat, cfg.horizon, "LSTM", progress)

        lstm_state, info["lstm_loss"] = _cached(
            cache, "lstm", {"frames": frame_spec, "cfg": dataclasses.asdict(lcfg),
                            "in_dim": enc.frame_dim, "horizon": cfg.horizon, "key": _key(k_l)},
            fit_lstm,
            lambda: jax.eval_shape(lambda: steps.init_lstm(k_l, lcfg, enc.frame_dim)))
    return Pretrained(scene_vae=scene, object_vae=obj_state, lstm=lstm_state), info


# ----------------------------------------------------------------------------- files

def recon_grid(params, cfg, images, path: str, n: int = 8) -> None:
    """Originals (top row) and reconstructions (bottom row) as a PNG, 4x upscaled."""
    import cv2

    x = images[:n]
    mean = models.encode_mean(params, cfg, x)
    rec = (np.asarray(models.decode(params, cfg, mean)) * 255).round().astype(np.uint8)
    grid = np.concatenate([np.concatenate(list(np.asarray(x)), 1), np.concatenate(list(rec), 1)], 0)
    grid = cv2.resize(grid, (grid.shape[1] * 4, grid.shape[0] * 4), interpolation=cv2.INTER_NEAREST)
    cv2.imwrite(path, grid[..., ::-1])


def task_revision(task: str) -> int:
    """The revision of `task`'s numbers (envs_mjx TaskSpec.revision) its encoders were
    pretrained on; a checkpoint that records none was made on revision 1."""
    from envs_mjx.tasks import TASKS

    return TASKS[task].revision


def _meta(cfg: TrainConfig) -> dict:
    enc = goal_encoder(cfg)
    return {"version": CHECKPOINT_VERSION, "task": cfg.task, "algo": cfg.algo,
                "task_revision": task_revision(cfg.task),
                "image_shape": list(cfg.scene.image_shape), "scene_latent": cfg.scene.latent_dim,
                "object_latent": None if enc.object_cfg is None else enc.object_cfg.latent_dim,
                "lstm": enc.lstm,
                # The ablations train the object-VAE without its matching loss: a checkpoint
                # trained with it must not serve them (nor the reverse).
                "object_matching_coef": None if enc.object_cfg is None
                else enc.object_cfg.matching_coef,
                "scene_decoder": cfg.scene.decoder,
                "object_decoder": None if enc.object_cfg is None else enc.object_cfg.decoder}


def save(path: str, cfg: TrainConfig, pre: Pretrained) -> None:
    import orbax.checkpoint as ocp

    path = write_meta(path, _meta(cfg))
    with ocp.StandardCheckpointer() as ck:
        ck.save(os.path.join(path, "encoders"), pre, force=True)


def initial(cfg: TrainConfig, key) -> Pretrained:
    """Freshly initialised (untrained) encoders of the config's shape."""
    enc = goal_encoder(cfg)
    k_s, k_o, k_l = jax.random.split(key, 3)
    return Pretrained(
        scene_vae=steps.init_vae(k_s, cfg.scene),
        object_vae=None if enc.object_cfg is None else steps.init_vae(k_o, enc.object_cfg),
        lstm=steps.init_lstm(k_l, cfg.lstm, enc.frame_dim) if enc.lstm else None)


def _abstract(cfg: TrainConfig) -> Pretrained:
    return jax.eval_shape(lambda: initial(cfg, jax.random.PRNGKey(0)))


def meta_decoders(meta: dict) -> dict:
    """The scene and object decoders an encoder checkpoint's meta records; a checkpoint written
    before the decoder was a choice has Table 3's ("deconv")."""
    return {"scene_decoder": meta.get("scene_decoder", "deconv"),
            "object_decoder": meta.get("object_decoder", None if meta.get("object_latent")
                                       is None else "deconv")}


def load(path: str, cfg: TrainConfig) -> Pretrained:
    """Restore; refuses a checkpoint for another task, image size or latent size."""
    import orbax.checkpoint as ocp

    path, meta = read_meta(path, "encoder")
    if meta.get("version") == 2:
        raise ValueError(
            f"encoder checkpoint {path} was pretrained on the earlier task numbers (a 40 x 30 cm "
            f"hand box on every push task, other hand resets, hurdle pretraining data only in "
            f"the goal strip); the tasks now use the reference code's (envs_mjx/tasks.py): "
            f"pretrain them again")
    if meta.get("version") != CHECKPOINT_VERSION:
        raise ValueError(
            f"encoder checkpoint {path} has version {meta.get('version')!r}, this code needs "
            f"{CHECKPOINT_VERSION}: version 1 encoders were trained with the KL weighted by beta "
            f"per image instead of the reference code's beta / batch (VAEConfig.effective_beta), "
            f"which collapses the object-VAE; pretrain them again")
    want = _meta(cfg)
    if meta.get("task_revision", 1) != want["task_revision"]:
        raise ValueError(
            f"encoder checkpoint {path} was pretrained on revision {meta.get('task_revision', 1)} "
            f"of task {cfg.task!r}, whose images are now those of revision "
            f"{want['task_revision']} (envs_mjx/tasks.py, TaskSpec.revision): pretrain them again")
    recorded = {**meta, **meta_decoders(meta)}
    for k in ("task", "image_shape", "scene_latent", "object_latent", "lstm",
              "object_matching_coef", "scene_decoder", "object_decoder"):
        got = recorded.get(k)
        if got != want[k]:
            raise ValueError(f"encoder checkpoint {path} has {k}={got!r}, but this run "
                             f"needs {k}={want[k]!r}")
    with ocp.StandardCheckpointer() as ck:
        return ck.restore(os.path.join(path, "encoders"), _abstract(cfg))


def main(argv=None) -> int:
    """`roll-pretrain` (roll_jax/encoders/cli.py, which parses before importing JAX)."""
    from roll_jax.encoders import cli

    return cli.main(argv)


def pretrain_command(cfg: TrainConfig, out: str, seg_dir: str | None, seed: int,
                     overrides: list[str]) -> dict:
    """What `roll-pretrain` does with a checked config: segmentation (fitted or loaded),
    pretraining, DIR/encoders, the reconstruction grids and DIR/pretrain.json."""
    import envs_mjx

    env = envs_mjx.make(cfg.task)
    key = jax.random.PRNGKey(seed)
    seg = None
    if goal_encoder(cfg).segment:
        seg = fit_or_load_segmentation(cfg, env, seg_dir or os.path.join(out, "segmentation"),
                                       jax.random.fold_in(key, 1))
    pre, info = pretrain(cfg, env, seg, key)
    save(os.path.join(out, "encoders"), cfg, pre)
    recon_grid(pre.scene_vae.params, cfg.scene, info["scene_data"],
               os.path.join(out, "recon_scene.png"))
    if pre.object_vae is not None:
        recon_grid(pre.object_vae.params, cfg.object_vae, info["object_data"],
                   os.path.join(out, "recon_object.png"))
    summary = {k: [v[0], v[-1]] for k, v in info.items() if k.endswith("_loss")}
    with open(os.path.join(out, "pretrain.json"), "w") as f:
        json.dump({"task": cfg.task, "preset": cfg.preset, "algo": cfg.algo,
                   "overrides": list(overrides), "loss_first_last": summary}, f, indent=2)
    print(json.dumps(summary, indent=2))
    return summary


def fit_or_load_segmentation(cfg: TrainConfig, env, path: str, key):
    """Load the task's segmentation from `path`, or fit it there first."""
    if os.path.exists(os.path.join(path, "meta.json")):
        params, _ = pipeline.load(path, cfg.task)
        return params
    params, _ = pipeline.fit(env, key, cfg.segmentation)
    pipeline.save(path, cfg.task, params, cfg.segmentation)
    return params


