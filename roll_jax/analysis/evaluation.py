"""A training run's policy evaluated on goal images, as at the paper's test time: the library
behind `roll-evaluate` (roll_jax/analysis/evaluate.py, whose help describes the outputs).

`load_run` loads a run's latest checkpoint with its segmentation and encoders, `evaluate` runs
the deterministic policy of every seed for one episode per goal (given images, or goals
sampled from the task's goal space), `write_outputs` writes the images, GIFs and
evaluation.json.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import os

import jax
import jax.numpy as jnp
import numpy as np

from configs.train import TrainConfig
from roll_jax.agents import sac
from roll_jax.common.checkpoint import restore_train_state, train_state_manager
from roll_jax.encoders import pretrain
from roll_jax.encoders.goal_encoding import Frozen, goal_encoder
from roll_jax.segmentation import pipeline
from roll_jax.training import driver, run_dir
from roll_jax.training.state import TrainState, lstm_params_of

IMAGE_SIZE = 48


@dataclasses.dataclass
class LoadedRun:
    cfg: TrainConfig
    env: object
    frozen: Frozen
    state: TrainState  # [seeds]-batched
    epoch: int


def input_paths(run: str) -> dict:
    """Where the run's segmentation and encoders are: DIR/inputs.json (written by the run:
    its --seg-ckpt / --enc-ckpt, or its own sub-directories)."""
    inputs = run_dir.read_inputs(run)
    return {"seg_ckpt": inputs.get("seg_ckpt", os.path.join(run, "segmentation")),
            "enc_ckpt": inputs.get("enc_ckpt", os.path.join(run, "encoders"))}


def load_run(run: str, seg_ckpt: str | None = None, enc_ckpt: str | None = None) -> LoadedRun:
    """The run's config, env, frozen parameters and its latest train state; clear errors for a
    directory that is not a run or has no checkpoint; the segmentation and encoder loaders
    refuse checkpoints of another task, naming them."""
    import envs_mjx

    cfg = run_dir.read_config(run)
    ckpt = os.path.join(run, "ckpt")
    mgr = train_state_manager(run, cfg.keep_checkpoints, create=False) if os.path.isdir(ckpt) \
        else None
    if mgr is None or mgr.latest_step() is None:
        raise FileNotFoundError(f"{run}: no checkpoint in {ckpt} (the run has not finished "
                                f"its first evaluation interval)")
    env = envs_mjx.make(cfg.task)
    enc = goal_encoder(cfg)
    inputs = input_paths(run)
    seg = None
    if enc.segment:
        seg, _ = pipeline.load(seg_ckpt or inputs["seg_ckpt"], cfg.task, cfg.scene.image_shape)
    if not enc.from_pixels:  # the oracle
        pre = pretrain.initial(cfg, jax.random.PRNGKey(0))
    else:
        pre = pretrain.load(enc_ckpt or inputs["enc_ckpt"], cfg)
    keys = jax.random.split(jax.random.PRNGKey(0), cfg.seeds)
    abstract = jax.eval_shape(lambda k: driver.init_states(cfg, env, k, pre), keys)
    def on_damaged(step: int, reason: str) -> None:  # the newest readable one is evaluated
        run_dir.warn(f"checkpoint {ckpt}/{step} is damaged ({reason}); trying the one before it")

    try:
        epoch, state = restore_train_state(mgr, abstract, on_damaged)
    finally:
        mgr.close()
    frozen = Frozen(seg=seg, object_vae=None if pre.object_vae is None else pre.object_vae.params)
    return LoadedRun(cfg=cfg, env=env, frozen=frozen, state=state, epoch=int(epoch))


def read_goal_image(path: str) -> tuple[np.ndarray, str | None]:
    """uint8 [48, 48, 3] of an RGB image file, and a note when it was resized."""
    from PIL import Image, UnidentifiedImageError

    try:
        img = Image.open(path)
        img.load()
    except (OSError, UnidentifiedImageError) as e:
        raise ValueError(f"goal image {path}: not an image ({e})") from None
    bands = img.getbands()
    if len(bands) != 3:
        raise ValueError(f"goal image {path}: {len(bands)} channel(s) (mode {img.mode}); "
                         f"expected an RGB image with 3")
    img = img.convert("RGB")
    note = None
    if img.size != (IMAGE_SIZE, IMAGE_SIZE):
        note = f"resized from {img.size[0]}x{img.size[1]} to {IMAGE_SIZE}x{IMAGE_SIZE}"
        img = img.resize((IMAGE_SIZE, IMAGE_SIZE), Image.BILINEAR)
    return np.asarray(img, np.uint8), note


@functools.lru_cache(maxsize=4)
def make_rollout(cfg: TrainConfig):
    """jit(vmap over seeds) of one deterministic episode per goal -> per seed: final env
    states [G], frames [G, T+1, 48, 48, 3], goal latents [G, g], final achieved latents
    [G, g]. Goals come as images (`goal_rgb`) and, for the oracle, as env states. Cached per
    config (its own env), so that every run loaded with one config runs one program."""
    import envs_mjx

    env = envs_mjx.make(cfg.task)
    enc = goal_encoder(cfg)

    def one_seed(frozen, state, goal_rgb, goal_states, key):
        g = goal_rgb.shape[0]
        scene, lstm = state.scene_vae.params, lstm_params_of(state)
        goals = enc.encode_goals(env, frozen, scene, lstm, goal_rgb, goal_states)
        k_start, k_ep = jax.random.split(key)
        starts = jax.vmap(env.reset)(jax.random.split(k_start, g))
        es = jax.vmap(env.reset_episode)(starts, jax.random.split(k_ep, g))
        every = slice(None)  # every env's frames (the GIFs)

        def step(es, _):
            z, rec, rgb = enc.observe(env, scene, es, every)
            a = sac.select_action(state.sac.policy_params, z, goals, None, deterministic=True,
                                  cfg=cfg.sac)
            return jax.vmap(env.step)(es, a), (rec, rgb)

        es, (recs, frames) = jax.lax.scan(step, es, None, length=cfg.horizon)
        _, rec, last = enc.observe(env, scene, es, every)
        episode_major = lambda xs, x: jnp.concatenate([xs, x[None]], 0).swapaxes(0, 1)  # noqa: E731
        frames = episode_major(frames, last)  # [G, T+1, ...]
        records = jax.tree.map(episode_major, recs, rec)
        achieved = enc.encode_episodes(frozen, scene, lstm, records)[3]
        return es, frames, goals, achieved[:, -1]

    return jax.jit(jax.vmap(one_seed, in_axes=(None, 0, None, None, None)))


@functools.partial(jax.jit, static_argnums=(0, 2))
def sample_goals(env, key, n: int):
    """n goal states from the task's goal space and their rendered 48x48 images."""
    states = jax.vmap(env.sample_goal)(jax.random.split(key, n))
    return states, jax.vmap(env.render)(states)


@functools.partial(jax.jit, static_argnums=(0, 2))
def _reset_states(env, key, n: int):
    """n copies of one reset state: the goal-state slot of goals given only as images."""
    return jax.tree.map(lambda x: jnp.broadcast_to(x, (n,) + x.shape), env.reset(key))


@functools.partial(jax.jit, static_argnums=0)
def _final_states(env, es, goal_states):
    """Final object states [S, G, k] and true distances to the goal states [S, G]."""
    per_seed = jax.vmap(jax.vmap(env.object_state))(es)
    dist = jax.vmap(lambda e: jax.vmap(env.goal_distance)(e, goal_states))(es)
    return per_seed, dist


def evaluate(loaded: LoadedRun, goal_images: list[np.ndarray] | None, n_goals: int,
             seed: int = 0) -> dict:
    """Arrays of the evaluation: goal images [G, ...], frames [S, G, T+1, ...], latent and
    (sampled goals only) true final distances [S, G], final object states [S, G, k]."""
    cfg, env = loaded.cfg, loaded.env
    k_goal, k_run = jax.random.split(jax.random.PRNGKey(seed))
    if goal_images:
        if not goal_encoder(cfg).from_pixels:
            raise ValueError("an oracle run acts on true goal states: goal images cannot be "
                             "evaluated (omit --goal-image to sample goals)")
        rgb = jnp.asarray(np.stack(goal_images), jnp.uint8)
        # no goal state behind a user's image: a reset state fills the (unused) slot
        goal_states = _reset_states(env, k_goal, rgb.shape[0])
        true_goal = False
    else:
        goal_states, rgb = sample_goals(env, k_goal, n_goals)
        true_goal = True
    es, frames, goals, achieved = make_rollout(cfg)(loaded.frozen, loaded.state, rgb,
                                                    goal_states, k_run)
    final_object, final_distance = _final_states(env, es, goal_states)
    out = {"goal_images": np.asarray(rgb), "frames": np.asarray(frames),
           "latent_distance": np.asarray(jnp.linalg.norm(achieved - goals, axis=-1)),
           "final_object_state": np.asarray(final_object)}
    if true_goal:
        out["final_distance"] = np.asarray(final_distance)
    return out


def write_outputs(out: str, loaded: LoadedRun, res: dict, sources: list[str],
                  notes: list[str | None], run: str, seed: int) -> dict:
    from PIL import Image

    os.makedirs(out, exist_ok=True)
    goals = []
    n_seeds = res["frames"].shape[0]
    for g, (src, note) in enumerate(zip(sources, notes)):
        Image.fromarray(res["goal_images"][g]).save(os.path.join(out, f"goal_{g:02d}.png"))
        for s in range(n_seeds):
            run_dir.write_gif(os.path.join(out, f"goal_{g:02d}_seed{s}.gif"), res["frames"][s, g],
                              res["goal_images"][g])
            Image.fromarray(res["frames"][s, g, -1]).save(
                os.path.join(out, f"final_{g:02d}_seed{s}.png"))
        row = {"goal": g, "source": src, "note": note,
               "latent_distance": res["latent_distance"][:, g].tolist(),
               "final_object_state": res["final_object_state"][:, g].tolist(),
               "final_distance": (res["final_distance"][:, g].tolist()
                                  if "final_distance" in res else None)}
        goals.append(row)
    summary = {"run": os.path.abspath(run), "task": loaded.cfg.task, "algo": loaded.cfg.algo,
               "checkpoint_epoch": loaded.epoch,
               "env_steps": loaded.epoch * loaded.cfg.epoch_env_steps, "seeds": n_seeds,
               "seed": seed, "goals": goals,
               "latent_distance_median": float(np.median(res["latent_distance"]))}
    if "final_distance" in res:
        summary["final_distance_median"] = float(np.median(res["final_distance"]))
        summary["final_distance_mean"] = float(np.mean(res["final_distance"]))
    with open(os.path.join(out, "evaluation.json"), "w") as f:
        json.dump(summary, f, indent=2)
    return summary
