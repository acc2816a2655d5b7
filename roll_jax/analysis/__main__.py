"""The analyses of pretrained encoders and trained runs (`roll-analysis CMD ...`).

    roll-analysis latent-vs-distance --task TASK --ckpt DIR [--n 500] [--out DIR]   (Fig. 5)
    roll-analysis occlusion --ckpt DIR [--task hurdle_top] [--out DIR]     (appendix A)
    roll-analysis reward-probe --run RUN [RUN ...] --out OUT       (object vs hand distance)
    roll-analysis diagnose --task TASK --run DIR [--out FILE]      (a push task's encoders)
    roll-analysis compare RUN_A RUN_B [--n-goals N]                (paired runs)
    roll-analysis policy-panel --evals OUT_A OUT_B --labels A B --out PNG

(`python -m roll_jax.analysis CMD ...` is the same.) `latent-vs-distance` and `occlusion`
read DIR = `python -m roll_jax.encoders.pretrain --task TASK --out DIR` (DIR/segmentation,
DIR/encoders, DIR/pretrain.json) and write to --out (default DIR/analysis); their JSON keys
follow docs/architecture.md ("Evaluation files"): `spearman_object`, `spearman_scene`;
`error_cm` = {"lstm_matching": [mean, std], "lstm": [...], "vae": [...]}. `CMD --help`
describes each command.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import sys

# Commands with their own parser: module, function.
DELEGATED = {"reward-probe": ("roll_jax.analysis.reward_probe", "main"),
             "diagnose": ("roll_jax.analysis.diagnose", "main"),
             "compare": ("roll_jax.analysis.compare", "main"),
             "policy-panel": ("roll_jax.analysis.compare", "panel_main")}
HELP = {"reward-probe": "what runs' reward encoders measure: object vs hand distance",
        "diagnose": "a push task's encoders, reset and prior goals, before tuning",
        "compare": "two runs paired: learning curves, final policies on shared goals",
        "policy-panel": "goal images and each run's final frames from roll-evaluate outputs"}


def make_parser() -> argparse.ArgumentParser:
    from configs.train import PRESETS, TASKS
    from roll_jax.analysis.occlusion import HURDLE_TASKS, OCCLUSION_DROP

    p = argparse.ArgumentParser(prog="roll-analysis", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="cmd", required=True, metavar="CMD")
    a1 = sub.add_parser("latent-vs-distance", help="paper Figure 5")
    a1.add_argument("--task", required=True, choices=TASKS, help="the checkpoint's task")
    a1.add_argument("--n", type=int, default=500, help="observations (default 500)")
    a2 = sub.add_parser("occlusion", help="appendix A occlusion retrieval")
    a2.add_argument("--task", default="hurdle_top", choices=HURDLE_TASKS,
                    help="a task with a hurdle path (default hurdle_top)")
    a2.add_argument("--n-train", type=int, default=None,
                    help="training trajectories (default: the preset's, configs/presets.py)")
    a2.add_argument("--n-eval", type=int, default=None,
                    help="evaluation trajectories = queries (default: the preset's)")
    a2.add_argument("--horizon", type=int, default=None, help="frames per trajectory (task's)")
    a2.add_argument("--lstm-steps", type=int, default=None,
                    help="steps per LSTM (default: the preset's)")
    a2.add_argument("--vae-steps", type=int, default=None,
                    help="object-VAE fine-tuning steps on the trajectories (default: the "
                         "preset's)")
    a2.add_argument("--batch", type=int, default=25, help="LSTM batch (trajectories), default 25")
    a2.add_argument("--drop", type=float, default=OCCLUSION_DROP,
                    help=f"share of the occluded frame's object pixels removed (default "
                         f"{OCCLUSION_DROP})")
    for a in (a1, a2):
        a.add_argument("--ckpt", required=True, metavar="DIR",
                       help="python -m roll_jax.encoders.pretrain --out DIR")
        a.add_argument("--out", default=None, help="default: CKPT/analysis")
        a.add_argument("--preset", default=None, choices=PRESETS,
                       help="default: the checkpoint's (pretrain.json)")
        a.add_argument("--seed", type=int, default=0, help="PRNG seed (default 0)")
    for name, text in HELP.items():  # listed here, parsed by their own modules
        sub.add_parser(name, help=text, add_help=False)
    return p


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv and argv[0] in DELEGATED:
        module, func = DELEGATED[argv[0]]
        getattr(importlib.import_module(module), func)(argv[1:])
        return 0
    a = make_parser().parse_args(argv)
    out = a.out or os.path.join(a.ckpt, "analysis")
    try:
        if a.cmd == "latent-vs-distance":
            from roll_jax.analysis.fig5 import run_latent_vs_distance

            res = run_latent_vs_distance(a.task, a.ckpt, out, a.n, a.seed, a.preset)
        else:
            from configs import presets
            from roll_jax.analysis.checkpoints import checkpoint_preset
            from roll_jax.analysis.occlusion import run_occlusion

            d = presets.get(checkpoint_preset(a.ckpt, a.task, a.preset)).for_task(
                "occlusion", a.task)
            res = run_occlusion(a.ckpt, out, a.task,
                                n_train=a.n_train or d["n_train"], n_eval=a.n_eval or d["n_eval"],
                                horizon=a.horizon,
                                lstm_steps=d["lstm_steps"] if a.lstm_steps is None else a.lstm_steps,
                                vae_steps=d["vae_steps"] if a.vae_steps is None else a.vae_steps,
                                batch=a.batch, drop=a.drop, seed=a.seed, preset=a.preset)
    except (FileNotFoundError, ValueError) as e:
        sys.exit(f"error: {e}")
    print(json.dumps(res, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
