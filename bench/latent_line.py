"""Latent distance along a line of object positions: is the reward's landscape one valley?

    python bench/latent_line.py --task puck_push --ckpt runs/pp_pre3 --name puck_push_cpu

The object is placed at --n positions along x across its goal box (y at the box's centre),
with the hand parked at --hand; each image is encoded by the object-VAE (of the segmented image), by the
goal encoder (object-VAE, then one LSTM step: ROLL's goal / reward latent) and by the
scene-VAE (the policy's observation). For a few goal positions it reports the latent distance from the goal's latent
to every position's. A distance that falls again towards the far end of the line (the two
ends of the line lie close in latent space) gives a reward with two uphill directions from
the middle: a policy can push the object away from the goal and still be rewarded.

Writes bench/results/latent_line_NAME.json (the profiles, and per goal the far-end "fold":
the drop from the profile's maximum to its far end, relative to that maximum) and
docs/images/latent_line_NAME.png. `--ckpt` holds segmentation/ and encoders/ (a pretrain
--out or a train.py run directory).
"""

from __future__ import annotations

import argparse
import json
import os
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)


def fold(profile: np.ndarray, goal: int) -> float:
    """How far the distance profile falls back from its maximum towards the end of the line
    away from the goal, relative to that maximum (0: monotone, one valley)."""
    far = profile[goal:] if goal < len(profile) // 2 else profile[:goal + 1][::-1]
    peak = float(far.max())
    return float((peak - far[-1]) / peak) if peak > 0 else 0.0


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--task", default="puck_push", choices=("puck_push", "hurdle_top",
                                                          "hurdle_bottom"))
    p.add_argument("--ckpt", required=True, help="dir with segmentation/ and encoders/")
    p.add_argument("--preset", default="cpu")
    p.add_argument("--name", required=True)
    p.add_argument("--n", type=int, default=31)
    p.add_argument("--hand", type=float, nargs=2, default=(0.0, 0.45), help="hand x y (m)")
    a = p.parse_args(argv)
    if a.n < 5:
        p.error(f"--n must be at least 5, got {a.n}")
    import jax
    import jax.numpy as jnp

    import envs_mjx
    from envs_mjx import scenes
    from roll_jax.encoders import models, pretrain
    from roll_jax.training import driver, plots
    from roll_jax.encoders.goal_encoding import goal_encoder
    from roll_jax.training.loop import Frozen
    from roll_jax.segmentation import pipeline

    cfg = build_config(a.task, "roll", a.preset, seeds=1, overrides=[])
    env = envs_mjx.make(a.task)
    seg, _ = pipeline.load(os.path.join(a.ckpt, "segmentation"), a.task, cfg.scene.image_shape)
    pre = pretrain.load(os.path.join(a.ckpt, "encoders"), cfg)
    frozen = Frozen(seg=seg, object_vae=pre.object_vae.params)
    spec = env.spec
    lo, hi = np.asarray(spec.object_goal_low), np.asarray(spec.object_goal_high)
    xs = np.linspace(lo[0], hi[0], a.n).astype(np.float32)
    y = np.float32((lo[1] + hi[1]) / 2)
    hand = jnp.array([a.hand[0], a.hand[1], scenes.HAND_Z_PUSH], jnp.float32)
    states = jax.vmap(lambda x: env.place(hand, jnp.stack([x, y])))(jnp.asarray(xs))
    rgb = jax.vmap(env.render)(states)
    enc = goal_encoder(cfg)
    frames = enc.frame_latents(frozen, pre.scene_vae.params, enc.goal_images(frozen, rgb))
    latents = {
        "object-VAE latent": np.asarray(frames, np.float64),
        "goal latent (object-VAE + LSTM)": np.asarray(enc.single(pre.lstm.params, frames),
                                                      np.float64),
        "scene latent (scene-VAE)": np.asarray(models.encode_mean(
            pre.scene_vae.params, cfg.scene, rgb), np.float64)}
    goals = sorted({1, a.n // 4, a.n // 2, 3 * a.n // 4, a.n - 2})
    out = {"name": a.name, "task": a.task, "ckpt": os.path.abspath(a.ckpt), "x": xs.tolist(),
           "y": float(y), "hand": list(a.hand),
           "command": "python bench/latent_line.py " + " ".join(argv if argv is not None
                                                               else sys.argv[1:]),
           "profiles": {}}
    for kind, z in latents.items():
        dist = {g: np.linalg.norm(z - z[g], axis=-1) for g in goals}
        out["profiles"][kind] = {f"{xs[g]:+.3f}": {"distance": d.tolist(), "fold": fold(d, g)}
                                 for g, d in dist.items()}
    plt = plots.pyplot()
    fig, axes = plt.subplots(1, len(latents), figsize=(4 * len(latents), 3), sharex=True)
    for ax, (kind, prof) in zip(axes, out["profiles"].items()):
        for gx, d in prof.items():
            ax.plot(xs * 100, d["distance"], label=f"goal x {float(gx) * 100:+.0f} cm")
        ax.set_title(kind, fontsize=9)
        ax.set_xlabel("object x (cm)")
        ax.set_ylabel("latent distance to the goal's")
    axes[0].legend(fontsize=6)
    fig.tight_layout()
    img = os.path.join(ROOT, "docs", "images", f"latent_line_{a.name}.png")
    fig.savefig(img, dpi=120)
    plt.close(fig)
    path = os.path.join(ROOT, "bench", "results", f"latent_line_{a.name}.json")
    with open(path, "w") as f:
        json.dump(out, f, indent=2)
    for kind, prof in out["profiles"].items():
        print(kind + ": fold per goal x " + ", ".join(
            f"{float(gx) * 100:+.0f} cm {d['fold']:.2f}" for gx, d in prof.items()))
    print(f"wrote {path} and {img}")
    return out


if __name__ == "__main__":
    main()
