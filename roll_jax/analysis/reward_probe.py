"""What each method's reward encoder measures: object distance or hand distance.

    roll-analysis reward-probe --run DIR [DIR ...] [--n 500] [--seed S] --out OUT

For each training run (its latest checkpoint, seed 0's encoders: the scene-VAE as online
training left it), `n` pairs of random placements (hand uniform in its box, object uniform in
its goal space, independently: `env.random_placement`), both rendered; the reward
encoder (the GoalEncoder of the run's config: segment -> object-VAE -> one LSTM step for
ROLL, the scene-VAE of the whole image for Skew-Fit) encodes both, and the latent distance
is ranked against the object distance (`env.goal_distance`) and the hand distance of the
pair. ROLL's reward should follow the object and ignore the hand; Skew-Fit's follows both
(why its policy aligns the arm: paper Fig. 6). Writes OUT/reward_probe.json and
OUT/reward_probe.png (latent vs object distance and vs hand distance, per run).
"""

from __future__ import annotations

import argparse
import functools
import json
import os

import numpy as np

from roll_jax.analysis.stats import distance_unit, spearman

# JAX and the encoders are imported where they are used: `--help` answers without them.


def placement_pairs(env, key, n: int):
    """(rgb_a, rgb_b [n, 48, 48, 3], object distances [n], hand distances [n]) of n pairs of
    independent random placements."""
    import jax
    import jax.numpy as jnp

    @jax.jit
    def run(keys):
        def one(k):
            ka, kb, kc, kd = jax.random.split(k, 4)
            a, b = env.random_placement(ka, kb), env.random_placement(kc, kd)
            return (env.render(a), env.render(b), env.goal_distance(a, b),
                    jnp.linalg.norm(env.hand_pos(a) - env.hand_pos(b)))

        return jax.lax.map(one, keys, batch_size=64)

    return tuple(np.asarray(x) for x in run(jax.random.split(key, n)))


def reward_latents(loaded, seed_index: int = 0):
    """images [B, 48, 48, 3] -> the run's reward latents [B, g] (seed `seed_index`)."""
    import jax

    from roll_jax.encoders.goal_encoding import goal_encoder

    cfg = loaded.cfg
    enc = goal_encoder(cfg)
    if not enc.from_pixels:
        raise ValueError(f"{cfg.algo} run: the oracle's reward uses true states, not images")
    # Only the encoders' leaves of that seed (not the replay buffer's), passed as arguments
    # rather than baked into the program as constants.
    lstm = loaded.state.lstm
    params = jax.tree.map(lambda x: x[seed_index], (
        loaded.state.scene_vae.params, None if lstm is None else lstm.params))
    encode = jax.jit(lambda frozen, p, rgb: enc.encode_goal_images(frozen, p[0], p[1], rgb))
    return functools.partial(encode, loaded.frozen, params)


def correlations(encode, pairs) -> dict:
    from roll_jax.analysis.checkpoints import batched

    rgb_a, rgb_b, d_obj, d_hand = pairs
    za, zb = batched(encode, rgb_a, 256), batched(encode, rgb_b, 256)
    d_z = np.linalg.norm(np.asarray(za, np.float64) - np.asarray(zb, np.float64), axis=-1)
    return {"spearman_object": spearman(d_obj, d_z), "spearman_hand": spearman(d_hand, d_z),
            "latent_distance": d_z.tolist()}


def plot(results: list[dict], pairs, path: str, x_scale: float, x_unit: str) -> None:
    from roll_jax.training.plots import pyplot

    plt = pyplot()
    _, _, d_obj, d_hand = pairs
    fig, axes = plt.subplots(len(results), 2, figsize=(7, 2.8 * len(results)), squeeze=False)
    for row, r in zip(axes, results):
        d_z = np.asarray(r["latent_distance"])
        row[0].scatter(d_obj * x_scale, d_z, s=3, alpha=0.5)
        row[0].set_xlabel(f"object distance ({x_unit})")
        row[0].set_title(f"{r['label']}: Spearman {r['spearman_object']:.2f}", fontsize=9)
        row[1].scatter(d_hand * 100, d_z, s=3, alpha=0.5, color="tab:orange")
        row[1].set_xlabel("hand distance (cm)")
        row[1].set_title(f"{r['label']}: Spearman {r['spearman_hand']:.2f}", fontsize=9)
        row[0].set_ylabel("reward latent distance")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(prog="roll-analysis reward-probe", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--run", nargs="+", required=True, metavar="RUN",
                   help="train.py --out directories (of one task; only read)")
    p.add_argument("--n", type=int, default=500, help="placement pairs (default 500)")
    p.add_argument("--seed", type=int, default=0,
                   help="PRNG seed of the placements (default 0)")
    p.add_argument("--out", required=True, metavar="OUT",
                   help="output directory: reward_probe.json, reward_probe.png")
    a = p.parse_args(argv)
    if a.n < 3:
        p.error(f"--n must be at least 3 (a rank correlation), got {a.n}")
    import jax

    from roll_jax.analysis import evaluation
    results, task, pairs = [], None, None
    try:
        for run in a.run:
            loaded = evaluation.load_run(run)
            if task is None:
                task = loaded.cfg.task
                pairs = placement_pairs(loaded.env, jax.random.PRNGKey(a.seed), a.n)
            elif loaded.cfg.task != task:
                raise ValueError(f"{run} is a {loaded.cfg.task} run, {a.run[0]} a {task} run: "
                                 f"compare runs of one task")
            r = correlations(reward_latents(loaded), pairs)
            label = loaded.cfg.algo + ("" if loaded.cfg.algo != "roll" else "".join(
                f" {f}" for f, on in (("no-matching", not loaded.cfg.matching_loss),
                                      ("no-lstm", not loaded.cfg.use_lstm),
                                      ("no-object-vae", not loaded.cfg.use_object_vae)) if on))
            results.append({"run": os.path.abspath(run), "label": label,
                            "env_steps": loaded.epoch * loaded.cfg.epoch_env_steps, **r})
            print(f"{label:28s} Spearman vs object {r['spearman_object']:+.3f}  vs hand "
                  f"{r['spearman_hand']:+.3f}  ({run})", flush=True)
    except (FileNotFoundError, ValueError) as e:
        p.error(str(e))
    os.makedirs(a.out, exist_ok=True)
    unit, scale = distance_unit(task)
    plot(results, pairs, os.path.join(a.out, "reward_probe.png"), scale, unit)
    summary = {"task": task, "n": a.n, "seed": a.seed,
               "runs": [{k: v for k, v in r.items() if k != "latent_distance"} for r in results]}
    with open(os.path.join(a.out, "reward_probe.json"), "w") as f:
        json.dump({**summary, "object_distance": pairs[2].tolist(),
                   "hand_distance": pairs[3].tolist(),
                   "latent_distance": [r["latent_distance"] for r in results]}, f)
    return summary


if __name__ == "__main__":
    main()
