"""How well object encoders rank the object on a trained policy's own frames.

The analysis (`python -m roll_jax.analysis latent-vs-distance`) scores encoders on random,
independent placements of arm and object. Learning sees other frames: the arm pushing the
object, the object moved by a few cm over an episode, HER comparing frames of one episode.
This rolls out a trained ROLL run's policy (sampled actions, as it collects its data) on goals
from the task's goal space, records each frame's true object state, and scores on those
frames the run's own encoders and any other encoder checkpoints (`--enc`, pretrained on the
same segmentation; each with its own decoder; or other runs' encoders), in three latent
spaces: the object-VAE means ("vae"), the encoder checkpoint's LSTM ("lstm_pretrained"), and
for a run's encoders the LSTM trained during that run ("lstm_online", seed by seed).

Per latent space:
- `goal_spearman`: latent vs true distance to the episode's goal over all frames (the reward);
- `goal_spearman_near`: the same over frames within `--near` cm of the goal (what the reward
  says where the policy is nearly done);
- `episode_spearman_median`: per episode whose object distance spans >= 2 cm, over time;
- `her_pair_spearman`: over frame pairs of one episode, latent vs object distance between the
  two frames (HER's future goals), and `her_pair_spearman_near` for pairs < `--near` cm apart;
- `arm_noise_cm`: median latent change between two frames of one episode whose object moved
  < 1 mm, in cm of object motion (divided by the median latent change per cm over pairs
  2-4 cm apart): how far the arm alone moves the reward.

    python bench/reward_on_policy.py --run runs/puck_push_roll_cpu --enc runs/sbd/puck_push
    python bench/reward_on_policy.py --run RUN_A --enc RUN_B   # B's encoders on A's frames

Writes bench/results/reward_on_policy_TASK.json (or --out).
"""
from __future__ import annotations

import argparse
import dataclasses
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from bench.common import machine_info, write_results  # noqa: E402
from roll_jax.agents import sac
from roll_jax.analysis import evaluation
from roll_jax.encoders import pretrain
from roll_jax.training import loop  # noqa: E402
from roll_jax.analysis import spearman  # noqa: E402
from roll_jax.common.checkpoint import read_meta  # noqa: E402
from roll_jax.encoders.goal_encoding import goal_encoder  # noqa: E402
from roll_jax.encoders.models import lstm_encode  # noqa: E402


def rollouts(loaded, n_goals: int, seed: int):
    """Per seed of the run, one sampled-action episode per goal: frames [S, G, T+1, 48, 48, 3],
    object states [S, G, T+1, k], goal images [G, ...] and goal object states [G, k]."""
    cfg, env = loaded.cfg, loaded.env
    enc = goal_encoder(cfg)
    k_goal, k_run = jax.random.split(jax.random.PRNGKey(seed))
    goal_states, goal_rgb = evaluation.sample_goals(env, k_goal, n_goals)

    def one_seed(frozen, state, key):
        goals = enc.encode_goal_images(frozen, state.scene_vae.params, state.lstm.params, goal_rgb)
        k_start, k_ep, k_act = jax.random.split(key, 3)
        starts = jax.vmap(env.reset)(jax.random.split(k_start, n_goals))
        es = jax.vmap(env.reset_episode)(starts, jax.random.split(k_ep, n_goals))

        def step(es, k):
            rgb = jax.vmap(env.render)(es)
            z = loop.scene_latents(cfg, state.scene_vae.params, rgb)
            a = sac.select_action(state.sac.policy_params, z, goals, k, cfg=cfg.sac)
            return jax.vmap(env.step)(es, a), (rgb, jax.vmap(env.object_state)(es))

        es, (rgb, obj) = jax.lax.scan(step, es, jax.random.split(k_act, cfg.horizon))
        rgb = jnp.concatenate([rgb, jax.vmap(env.render)(es)[None]], 0)
        obj = jnp.concatenate([obj, jax.vmap(env.object_state)(es)[None]], 0)
        return rgb.swapaxes(0, 1), obj.swapaxes(0, 1)

    run = jax.jit(jax.vmap(one_seed, in_axes=(None, 0, 0)))
    frames, obj = run(loaded.frozen, loaded.state, jax.random.split(k_run, cfg.seeds))
    goal_obj = jax.vmap(env.object_state)(goal_states)
    return (np.asarray(frames), np.asarray(obj), np.asarray(goal_rgb), np.asarray(goal_obj))


def encoder_config(cfg, enc_dir: str):
    """The run's config with the object-VAE decoder of the checkpoint at enc_dir."""
    _, meta = read_meta(enc_dir, "encoder")
    decoder = pretrain.meta_decoders(meta)["object_decoder"]
    return dataclasses.replace(cfg, object_vae=dataclasses.replace(cfg.object_vae,
                                                                   decoder=decoder)), decoder


def latent_spaces(loaded, enc_dir: str, frames, goal_rgb, online_lstm=None) -> tuple[str, dict]:
    """(the checkpoint's object decoder, {name: (achieved [S, G, T+1, d], goal latents
    [S, G, d])}) of one encoder checkpoint, on the run's segmentation; `online_lstm`: a run's
    [seeds]-batched LSTM parameters trained with these encoders."""
    cfg, decoder = encoder_config(loaded.cfg, enc_dir)
    enc = goal_encoder(cfg)
    pre = pretrain.load(enc_dir, cfg)
    frozen = loaded.frozen.replace(object_vae=pre.object_vae.params)
    s, g, t1 = frames.shape[:3]

    @jax.jit
    def vae(images):
        return enc.frame_latents(frozen, None, enc.goal_images(frozen, images))

    z = np.stack([np.asarray(vae(jnp.asarray(frames[i].reshape((-1,) + frames.shape[3:]))))
                  for i in range(s)]).reshape(s, g, t1, -1)
    zg = np.asarray(vae(jnp.asarray(goal_rgb)))
    seq = jax.jit(jax.vmap(lstm_encode, in_axes=(None, 0)))
    one = jax.jit(lambda p, x: lstm_encode(p, x[:, None])[:, 0])
    spaces = {"vae": (z, np.broadcast_to(zg, (s,) + zg.shape))}
    p = pre.lstm.params
    spaces["lstm_pretrained"] = (np.stack([np.asarray(seq(p, z[i])) for i in range(s)]),
                                 np.stack([np.asarray(one(p, zg))] * s))
    if online_lstm is not None:
        ps = [jax.tree.map(lambda x, i=i: x[i], online_lstm) for i in range(s)]
        spaces["lstm_online"] = (np.stack([np.asarray(seq(ps[i], z[i])) for i in range(s)]),
                                 np.stack([np.asarray(one(ps[i], zg)) for i in range(s)]))
    return decoder, spaces


def scores(achieved, goal_lat, obj, goal_obj, near_cm: float, seed: int) -> dict:
    """The statistics of the module docstring for one latent space (distances in cm); the
    same frame pairs for every space of one seed."""
    rng = np.random.default_rng(seed)
    s, g, t1, _ = achieved.shape
    d_true = 100 * np.linalg.norm(obj - goal_obj[None, :, None], axis=-1)  # [S, G, T+1]
    d_lat = np.linalg.norm(achieved - goal_lat[:, :, None], axis=-1)
    near = d_true < near_cm
    per_episode = [spearman(d_true[i, j], d_lat[i, j]) for i in range(s) for j in range(g)
                   if np.ptp(d_true[i, j]) >= 2.0]
    ti, tj = np.triu_indices(t1, 1)
    pair_obj = 100 * np.linalg.norm(obj[:, :, ti] - obj[:, :, tj], axis=-1).ravel()
    pair_lat = np.linalg.norm(achieved[:, :, ti] - achieved[:, :, tj], axis=-1).ravel()
    pick = rng.choice(pair_obj.size, min(pair_obj.size, 20000), replace=False)
    po, pl = pair_obj[pick], pair_lat[pick]
    still, apart = po < 0.1, (po >= 2.0) & (po <= 4.0)
    slope = float(np.median(pl[apart] / po[apart])) if apart.any() else float("nan")
    close = po < near_cm
    return {
        "goal_spearman": spearman(d_true, d_lat),
        "goal_spearman_near": spearman(d_true[near], d_lat[near]) if near.sum() > 10 else None,
        "frames_near": int(near.sum()),
        "episode_spearman_median": float(np.median(per_episode)) if per_episode else None,
        "episodes_moving": len(per_episode),
        "her_pair_spearman": spearman(po, pl),
        "her_pair_spearman_near": spearman(po[close], pl[close]) if close.sum() > 10 else None,
        "latent_per_cm": slope,
        "arm_noise_cm": float(np.median(pl[still]) / slope) if still.any() else None,
        "still_pairs": int(still.sum()),
        "latent_goal_distance_median": float(np.median(d_lat)),
    }


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--run", required=True, help="a ROLL train.py --out directory")
    p.add_argument("--enc", nargs="*", default=[],
                   help="other encoders to score: `roll_jax.pretrain --out` directories, "
                        "or runs of the same task and seed count (their online LSTMs too)")
    p.add_argument("--n-goals", type=int, default=32)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--near", type=float, default=3.0, help="cm")
    p.add_argument("--out", default=None)
    a = p.parse_args(argv)
    loaded = evaluation.load_run(a.run)
    if loaded.cfg.algo != "roll" or not loaded.cfg.use_lstm:
        raise SystemExit(f"{a.run}: a ROLL run with its LSTM is needed, got algo "
                         f"{loaded.cfg.algo!r} (use_lstm={loaded.cfg.use_lstm})")
    if loaded.env.kind == "door":
        raise SystemExit("door_open: the object distance is an angle; not supported here")
    frames, obj, goal_rgb, goal_obj = rollouts(loaded, a.n_goals, a.seed)
    moved = 100 * np.linalg.norm(obj[:, :, -1] - obj[:, :, 0], axis=-1)
    res = {"command": " ".join(sys.argv), "run": a.run, "task": loaded.cfg.task,
           "checkpoint_epoch": loaded.epoch, "n_goals": a.n_goals, "seed": a.seed,
           "near_cm": a.near, "object_moved_cm_median": float(np.median(moved)),
           "final_distance_cm_median": float(np.median(
               100 * np.linalg.norm(obj[:, :, -1] - goal_obj[None], axis=-1))),
           "machine": machine_info(), "encoders": {}}
    sources = [(a.run, evaluation.input_paths(a.run)["enc_ckpt"], loaded.state.lstm.params)]
    for d in a.enc:
        if os.path.exists(os.path.join(d, "config.json")):
            other = evaluation.load_run(d)
            if other.cfg.seeds != loaded.cfg.seeds:
                raise SystemExit(f"{d}: {other.cfg.seeds} seeds, {a.run} has {loaded.cfg.seeds}")
            sources.append((d, evaluation.input_paths(d)["enc_ckpt"], other.state.lstm.params))
        else:  # a `roll_jax.pretrain --out` directory holds its checkpoint in encoders/
            sub = os.path.join(d, "encoders")
            sources.append((d, sub if os.path.exists(os.path.join(sub, "meta.json")) else d, None))
    for name, enc_dir, online in sources:
        decoder, spaces = latent_spaces(loaded, enc_dir, frames, goal_rgb, online)
        res["encoders"][name] = {"checkpoint": enc_dir, "object_decoder": decoder, **{
            space: scores(ach, gl, obj, goal_obj, a.near, a.seed)
            for space, (ach, gl) in spaces.items()}}
    print(f"{loaded.cfg.task}: object moved {res['object_moved_cm_median']:.1f} cm (median), "
          f"final distance {res['final_distance_cm_median']:.1f} cm")
    keys = ("goal_spearman", "goal_spearman_near", "episode_spearman_median",
            "her_pair_spearman", "her_pair_spearman_near", "arm_noise_cm")
    print(f"{'encoder':40s} {'space':16s} " + " ".join(f"{k[:14]:>14s}" for k in keys))
    for enc_dir, r in res["encoders"].items():
        for name in ("vae", "lstm_pretrained", "lstm_online"):
            if name in r:
                vals = [r[name][k] for k in keys]
                print(f"{enc_dir[-40:]:40s} {name:16s} " + " ".join(
                    f"{v:14.3f}" if v is not None else f"{'-':>14s}" for v in vals))
    write_results(a.out or os.path.join(ROOT, "bench", "results",
                                        f"reward_on_policy_{loaded.cfg.task}.json"), res)
    return res


if __name__ == "__main__":
    main()
