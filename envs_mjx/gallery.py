"""Render every task at its reset (and one goal) at 48x48 and 128x128, as PNGs.

    python -m envs_mjx.gallery --out docs/images
"""

from __future__ import annotations

import argparse
import os

import jax
import matplotlib.pyplot as plt
import numpy as np

import envs_mjx

LABEL_COLOURS = np.array([[0, 0, 0], [220, 60, 60], [60, 120, 240]], np.uint8)


def gallery(out: str, key_seed: int = 0) -> list[str]:
    os.makedirs(out, exist_ok=True)
    written = []
    for task in envs_mjx.TASK_NAMES:
        env = envs_mjx.make(task)
        key = jax.random.PRNGKey(key_seed)
        states = {"reset": jax.jit(env.reset)(key), "goal": jax.jit(env.sample_goal)(key)}
        for name, state in states.items():
            for size in (48, 128):
                rgb, lab = jax.jit(lambda s: env.render_both(s, size, size))(state)
                path = os.path.join(out, f"{task}_{name}_{size}.png")
                plt.imsave(path, np.asarray(rgb))
                written.append(path)
                if size == 128 and name == "reset":
                    path = os.path.join(out, f"{task}_{name}_{size}_labels.png")
                    plt.imsave(path, LABEL_COLOURS[np.asarray(lab)])
                    written.append(path)
    return written


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--out", default="docs/images")
    args = p.parse_args()
    for path in gallery(args.out):
        print(path)


if __name__ == "__main__":
    main()
