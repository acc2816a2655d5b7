"""Does an object-VAE trained to see through the arm rank partly hidden objects better?

The paper's VAE matching loss pulls the code of an image towards that of a copy with random
object pixels dropped. This experiment adds a second matching term between two renderings of
one object state with the hand at two random places in its box (`--pair-coef`), so the pairs
differ by what the arm really hides. Both renderings are segmented with the task's fitted
segmentation, as any training image. Everything else is the checkpoint's object-VAE config
(its beta, batch, steps, pixel-drop matching and occluded pretraining share), trained here
from scratch on 2000 such pairs, with and without the new term.

It scores the object-VAE's means (no LSTM) on the latent-vs-distance command's observation
sets (`analysis.observation_set`, analysis seeds given): Fig. 5's Spearman against the goal's
code, the affine r2 of the object state and the pairwise Spearman, on all observations and
on the partly hidden ones (20-80% of the object visible).

    python bench/arm_matching.py --ckpt runs/enc_cpu_z/hurdle_top --task hurdle_top \
        --pair-coef 0 8 32 128 --init-seeds 0 1

Writes bench/results/arm_matching_TASK.json after each run.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from bench.common import cpu_model  # noqa: E402

N_PAIRS, CHUNK = 2000, 250


def pair_data(env, seg, key, n: int):
    """Segmented images A, B uint8 [n, 48, 48, 3] and their object masks of n object states,
    each rendered with the hand at two random places in its box."""
    import jax
    import jax.numpy as jnp

    from roll_jax.segmentation import pipeline

    @jax.jit
    def batch(keys):
        def one(k):
            k_h1, k_obj, k_h2 = jax.random.split(k, 3)
            a = env.random_placement(k_h1, k_obj)
            b = env.place(env.random_hand(k_h2), env.object_state(a))
            return env.render(a), env.render(b)

        ra, rb = jax.vmap(one)(keys)
        ma, mb = pipeline.segment(seg, ra), pipeline.segment(seg, rb)
        return (pipeline.segmented_image(ra, ma), ma, pipeline.segmented_image(rb, mb), mb)

    parts = [batch(jax.random.split(jax.random.fold_in(key, i), CHUNK)) for i in range(n // CHUNK)]
    return tuple(jnp.concatenate(p) for p in zip(*parts))


def train(cfg, key, a, ma, b, mb, pair_coef: float, steps: int):
    """The object-VAE's loss on A (pixel-drop matching on A included) + pair_coef x the batch
    mean of ||mu(A) - mu(B)||^2, Adam as in pretraining."""
    import jax
    import optax

    from roll_jax.encoders import losses, models, steps
    from roll_jax.encoders.models import ConvVAE

    model = models.vae_model(cfg)
    opt = steps.vae_optimizer(cfg)
    n = a.shape[0]

    def loss_fn(p, xa, xb, mask_a, k):
        k_occ, k_noise = jax.random.split(k)
        occ = losses.OCCLUSIONS[cfg.occlusion_shape](k_occ, xa, mask_a, cfg.occlusion_drop)
        noise = jax.random.normal(k_noise, (xa.shape[0], cfg.latent_dim))
        loss, m = losses.vae_loss(p, model, xa, noise, cfg.effective_beta,
                                  occluded=occ if cfg.matching_coef > 0 else None,
                                  matching_coef=cfg.matching_coef,
                                  one_sided=cfg.matching_one_sided,
                                  recon_reduction=cfg.recon_reduction)
        mu_a, _ = model.apply(p, xa, method=ConvVAE.encode)
        mu_b, _ = model.apply(p, xb, method=ConvVAE.encode)
        pair = losses.matching_distance(mu_a, mu_b).mean()
        return loss + pair_coef * pair, {**m, "pair": pair}

    @jax.jit
    def run(state, key):
        def body(st, k):
            k_i, k_l, k_swap = jax.random.split(k, 3)
            idx = jax.random.randint(k_i, (cfg.batch_size,), 0, n)
            # Either rendering may be the one the batch reconstructs.
            swap = jax.random.bernoulli(k_swap, 0.5, (cfg.batch_size, 1, 1))
            xa = jax.numpy.where(swap[..., None], b[idx], a[idx])
            xb = jax.numpy.where(swap[..., None], a[idx], b[idx])
            mask_a = jax.numpy.where(swap, mb[idx], ma[idx])
            (_, m), g = jax.value_and_grad(loss_fn, has_aux=True)(st.params, xa, xb, mask_a, k_l)
            upd, opt_state = opt.update(g, st.opt_state, st.params)
            return st.replace(params=optax.apply_updates(st.params, upd), opt_state=opt_state,
                              step=st.step + 1), m
        return jax.lax.scan(body, state, jax.random.split(key, steps))

    state, m = run(steps.init_vae(key, cfg), jax.random.fold_in(key, 1))
    return state, {k: float(v[-100:].mean()) for k, v in m.items()}


def score(env, seg, params, cfg, seed: int, n: int) -> dict:
    import jax
    import numpy as np

    from roll_jax import analysis
    from roll_jax.encoders import models, steps
    from roll_jax.segmentation import pipeline

    obs = analysis.observation_set(env, jax.random.PRNGKey(seed), n)

    def encode(rgb):
        masks = pipeline.segment(seg, rgb)
        return np.asarray(models.encode_mean(params, cfg, pipeline.segmented_image(rgb, masks)),
                          np.float64)

    mu, mu_goal = encode(obs.rgb), encode(obs.goal_rgb[None])[0]
    vis = analysis.object_visibility(obs.labels)
    part = (vis >= analysis.HIDDEN_SHARE) & (vis < analysis.WHOLE_SHARE)
    d = np.linalg.norm(mu - mu_goal, axis=-1)
    return {"fig5_vae": analysis.spearman(obs.distances, d),
            "r2": analysis.position_r2(mu, obs.states),
            "pairwise": analysis.pairwise_spearman(mu, obs.states),
            "partly_hidden_fig5_vae": analysis.spearman(obs.distances[part], d[part]),
            "partly_hidden_n": int(part.sum())}


def main(argv=None) -> None:
    import jax
    import numpy as np

    import envs_mjx
    from roll_jax import analysis
    from roll_jax.encoders import pretrain
    from roll_jax.encoders.goal_encoding import goal_encoder

    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--ckpt", required=True, help="a pretraining dir (its segmentation and config)")
    p.add_argument("--task", default="hurdle_top")
    p.add_argument("--pair-coef", nargs="+", type=float, default=[0.0, 8.0])
    p.add_argument("--init-seeds", nargs="+", type=int, default=[0])
    p.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2, 3, 4],
                   help="analysis seeds (observation sets)")
    p.add_argument("--n", type=int, default=500)
    p.add_argument("--out", default=None)
    a = p.parse_args(argv)
    if any(c < 0 for c in a.pair_coef):
        p.error(f"--pair-coef must be >= 0, got {a.pair_coef}")
    out = a.out or os.path.join(ROOT, "bench", "results", f"arm_matching_{a.task}.json")
    cfg, _, seg = analysis.load_checkpoint(a.ckpt, a.task)
    ocfg = goal_encoder(cfg).object_cfg
    env = envs_mjx.make(a.task)
    t0 = time.time()
    xa, ma, xb, mb = pair_data(env, seg, jax.random.PRNGKey(7), N_PAIRS)
    if ocfg.pretrain_occluded_fraction > 0:  # the preset's occluded share, on both renderings
        xa, ma = pretrain.occlude_share(jax.random.PRNGKey(8), xa, ma,
                                        ocfg.pretrain_occluded_fraction,
                                        ocfg.pretrain_occluded_drop)
        xb, mb = pretrain.occlude_share(jax.random.PRNGKey(9), xb, mb,
                                        ocfg.pretrain_occluded_fraction,
                                        ocfg.pretrain_occluded_drop)
    res = {"task": a.task, "ckpt": a.ckpt, "cpu_model": cpu_model(), "n_pairs": N_PAIRS,
           "steps": ocfg.epochs * ocfg.batches_per_epoch, "object_vae": dataclasses.asdict(ocfg),
           "data_s": round(time.time() - t0, 1), "runs": []}
    print(f"pairs in {res['data_s']} s; object pixels A {float(ma.sum((1, 2)).mean()):.1f}, "
          f"B {float(mb.sum((1, 2)).mean()):.1f}", flush=True)
    for init in a.init_seeds:
        for coef in a.pair_coef:
            t = time.time()
            state, losses_end = train(ocfg, jax.random.PRNGKey(init), xa, ma, xb, mb, coef,
                                      res["steps"])
            scores = [score(env, seg, state.params, ocfg, s, a.n) for s in a.seeds]
            row = {"pair_coef": coef, "init_seed": init, "seconds": round(time.time() - t, 1),
                   "final_losses": losses_end,
                   **{k: [round(s[k], 4) for s in scores] for k in scores[0]}}
            res["runs"].append(row)
            print(json.dumps({k: row[k] for k in ("pair_coef", "init_seed", "seconds", "fig5_vae",
                                                  "r2", "pairwise", "partly_hidden_fig5_vae")}),
                  flush=True)
            with open(out, "w") as f:
                json.dump(res, f, indent=1)
    print("wrote", out, "mean fig5:", {r["pair_coef"]: float(np.mean(r["fig5_vae"]))
                                       for r in res["runs"]})


if __name__ == "__main__":
    main()
