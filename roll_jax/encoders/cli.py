"""Pretrain a task's encoders on their own (`roll-pretrain`, `python -m roll_jax.encoders.pretrain`).

    roll-pretrain --task TASK [--preset smoke|cpu|paper] [--algo roll|skewfit] --out DIR
        [--seg DIR] [--seed S] [--set object_vae.occlusion_shape=edge ...]

Fits the task's segmentation (or loads --seg), pretrains the scene-VAE, the object-VAE and the
LSTM as a training run does before its first chunk, and writes DIR/encoders (orbax +
meta.json), DIR/segmentation, DIR/recon_scene.png, DIR/recon_object.png and DIR/pretrain.json
(task, preset, --set overrides, first and last losses), which the analyses read
(`roll-analysis latent-vs-distance --ckpt DIR`, `occlusion --ckpt DIR`) and `train.py
--enc-ckpt DIR/encoders --seg-ckpt DIR/segmentation` reuses. The arguments are checked
before JAX loads.
"""

from __future__ import annotations

import argparse
import sys

DEFAULT_PRESET = "cpu"


def make_parser() -> argparse.ArgumentParser:
    from configs.encoders import ALGOS
    from configs.train import PRESETS, TASKS

    p = argparse.ArgumentParser(prog="roll-pretrain", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--task", required=True, metavar="TASK", help=f"one of {', '.join(TASKS)}")
    p.add_argument("--preset", default=DEFAULT_PRESET, metavar="PRESET",
                   help=f"one of {', '.join(PRESETS)} (configs/presets.py; default "
                        f"{DEFAULT_PRESET})")
    p.add_argument("--algo", default="roll", metavar="ALGO",
                   help=f"one of {', '.join(ALGOS)} (default roll): whose encoders (Skew-Fit "
                        "has no object-VAE or LSTM)")
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    p.add_argument("--seg", default=None, metavar="DIR",
                   help="segmentation checkpoint directory to use (default: fit one into "
                        "DIR/segmentation, or load it from there)")
    p.add_argument("--seed", type=int, default=0,
                   help="PRNG seed of the data and the initialisations (default 0)")
    p.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE",
                   help="config overrides as train.py's, e.g. object_vae.occlusion_shape=edge")
    return p


def main(argv=None) -> int:
    from configs.encoders import ALGOS
    from configs.train import PRESETS, TASKS, build_config

    p = make_parser()
    a = p.parse_args(argv)
    if a.task not in TASKS:
        p.error(f"unknown --task {a.task!r}; expected one of {', '.join(TASKS)}")
    if a.preset not in PRESETS:
        p.error(f"unknown --preset {a.preset!r}; expected one of {', '.join(PRESETS)}")
    if a.algo not in ALGOS:
        p.error(f"unknown --algo {a.algo!r}; expected one of {', '.join(ALGOS)} (the state "
                "oracle has no encoders to pretrain)")
    try:
        cfg = build_config(a.task, a.algo, a.preset, overrides=a.set)
    except (ValueError, TypeError) as e:
        sys.exit(f"roll-pretrain: error: {e}")
    from roll_jax.encoders import pretrain  # JAX: only once the arguments are known to be good

    pretrain.pretrain_command(cfg, a.out, a.seg, a.seed, a.set)
    return 0


if __name__ == "__main__":
    sys.exit(main())
