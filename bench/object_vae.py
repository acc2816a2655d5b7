"""Does the object-VAE encode where the object is? Trains it on segmented puck_push images
(object uniform in its goal space, hand uniform in its box, segmented with a fitted
`segment`) and reports, every 250 steps, on 500 held-out images: the per-dimension spread of
the latent means, R^2 of a linear fit of the puck's (x, y) from them, and the Spearman
correlation between pairwise latent and pairwise puck distances.

    python bench/object_vae.py --seg runs/seg/puck_push/ckpt --steps 1500 --name paper
    python bench/object_vae.py --seg ... --name beta1_nomatch --set beta=1 matching_coef=0
    python bench/object_vae.py --seg gt ...            # ground-truth masks (segmentation's bound)
    python bench/object_vae.py --seg ... --scene ...   # the scene-VAE on the whole images

`--set` overrides `object_vae_config("puck_push")` fields (the paper's values by default).
Appends one entry per run to bench/results/object_vae.json. See docs/analysis.md.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import time

import jax
import jax.numpy as jnp
import numpy as np

import envs_mjx
from configs.encoders import VAEConfig, object_vae_config, scene_vae_config
from configs.overrides import field_overrides
from roll_jax import analysis
from roll_jax.encoders import models, steps
from roll_jax.segmentation import pipeline

RESULTS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "results", "object_vae.json")
N_IMAGES, N_TEST, STEPS_PER_CALL, EVAL_EVERY = 2000, 500, 50, 250


def segmented_data(env, seg, seed: int, n: int):
    """Segmented images, object masks and object states of `n` random placements; `seg=None`
    segments with the renderer's ground-truth labels (an upper bound for `segment`)."""
    @jax.jit
    def batch(keys):
        def one(k):
            st = env.random_placement(*jax.random.split(k))
            rgb, labels = env.render_both(st)
            return rgb, labels, env.object_state(st)

        rgb, labels, pos = jax.vmap(one)(keys)
        masks = labels == 2 if seg is None else pipeline.segment(seg, rgb)
        return pipeline.segmented_image(rgb, masks), masks, pos, rgb

    parts = [batch(jax.random.split(jax.random.PRNGKey(seed + i), 250)) for i in range(n // 250)]
    return tuple(jnp.concatenate(p) for p in zip(*parts))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seg", required=True,
                    help="a puck_push segmentation checkpoint dir, or 'gt' for ground-truth masks")
    ap.add_argument("--scene", action="store_true",
                    help="train the scene-VAE config on the whole (unsegmented) images instead")
    ap.add_argument("--steps", type=int, default=1500)
    ap.add_argument("--n-train", type=int, default=N_IMAGES - N_TEST,
                    help="training images (a multiple of 250); 500 more are held out")
    ap.add_argument("--name", default="paper")
    ap.add_argument("--seed", type=int, default=0,
                    help="the VAE's initialisation and batches (the data stays the same)")
    ap.add_argument("--set", nargs="*", default=[], metavar="FIELD=VALUE")
    a = ap.parse_args()
    if a.steps < EVAL_EVERY or a.steps % EVAL_EVERY:
        raise SystemExit(f"--steps must be a positive multiple of {EVAL_EVERY}, got {a.steps}")
    if a.n_train <= 0 or a.n_train % 250:
        raise SystemExit(f"--n-train must be a positive multiple of 250, got {a.n_train}")
    try:
        make = scene_vae_config if a.scene else object_vae_config
        cfg = make("puck_push", **field_overrides(VAEConfig, a.set))
    except ValueError as e:
        raise SystemExit(f"error: {e}") from None
    env = envs_mjx.make("puck_push")
    seg = None if a.seg == "gt" else pipeline.load(a.seg, "puck_push")[0]
    t0 = time.time()
    # The held-out images come from their own keys, so they are the same for any --n-train.
    images, masks, pos, rgb = (jnp.concatenate(p) for p in zip(
        segmented_data(env, seg, 0, a.n_train), segmented_data(env, seg, 10_000, N_TEST)))
    if a.scene:
        images = rgb
    n_train = a.n_train
    test_images, test_xy = images[n_train:], np.asarray(pos[n_train:])[:, :2]
    print(f"data {time.time() - t0:.0f} s, object pixels per image "
          f"{float(masks.sum((1, 2)).mean()):.1f}", flush=True)

    @jax.jit
    def train(state, key):
        def body(st, k):
            k_i, k_s = jax.random.split(k)
            idx = jax.random.randint(k_i, (cfg.batch_size,), 0, n_train)
            m = masks[idx] if cfg.matching_coef > 0 else None
            return steps.vae_train_step(st, k_s, images[idx], cfg, m)
        return jax.lax.scan(body, state, jax.random.split(key, STEPS_PER_CALL))

    rng = np.random.default_rng(0)
    pi, pj = rng.integers(0, N_TEST, 3000), rng.integers(0, N_TEST, 3000)
    state = steps.init_vae(jax.random.PRNGKey(a.seed), cfg)
    rows = []
    for it in range(a.steps // STEPS_PER_CALL):
        state, m = train(state, jax.random.fold_in(jax.random.PRNGKey(100 + it), a.seed)
                         if a.seed else jax.random.PRNGKey(100 + it))
        step = (it + 1) * STEPS_PER_CALL
        if step % EVAL_EVERY:
            continue
        mu = np.asarray(models.encode_mean(state.params, cfg, test_images), np.float64)
        x = np.c_[mu, np.ones(len(mu))]
        coef, *_ = np.linalg.lstsq(x, test_xy, rcond=None)
        r2 = 1 - ((x @ coef - test_xy) ** 2).sum() / ((test_xy - test_xy.mean(0)) ** 2).sum()
        dz = np.linalg.norm(mu[pi] - mu[pj], axis=1)
        dp = np.linalg.norm(test_xy[pi] - test_xy[pj], axis=1)
        row = {"step": step, "seconds": round(time.time() - t0),
               **{k: float(v.mean()) for k, v in m.items()},
               "mu_std": np.round(mu.std(0), 4).tolist(), "r2_xy": float(r2),
               "spearman_pairs": analysis.spearman(dp, dz)}
        rows.append(row)
        print(json.dumps(row), flush=True)
    results = []
    if os.path.exists(RESULTS):
        with open(RESULTS) as f:
            results = json.load(f)
    results.append({"name": a.name, "seed": a.seed, "model": "scene" if a.scene else "object",
                    "config": dataclasses.asdict(cfg), "seg": a.seg,
                    "n_train": n_train, "n_test": N_TEST, "jax_backend": jax.default_backend(),
                    "rows": rows})
    os.makedirs(os.path.dirname(RESULTS), exist_ok=True)
    with open(RESULTS, "w") as f:
        json.dump(results, f, indent=1)
    print("wrote", RESULTS)


if __name__ == "__main__":
    main()
