"""The analyses of pretrained encoders and trained runs (`roll-analysis CMD ...`).

    roll-analysis latent-vs-distance (--ckpt DIR | --run RUN --out OUT) [--n 500]   (Fig. 5)
    roll-analysis occlusion (--ckpt DIR | --run RUN --out OUT) [--task hurdle_top] (appendix A)
    roll-analysis reward-probe --run RUN [RUN ...] --out OUT       (object vs hand distance)
    roll-analysis diagnose --task TASK --run DIR [--out FILE]      (a push task's encoders)
    roll-analysis compare RUN_A RUN_B [--n-goals N]                (paired runs; roll-compare)
    roll-analysis policy-panel --evals OUT_A OUT_B --labels A B --out PNG
    roll-analysis figure4 --cell TASK ALGO RUN [--cell ...] --png PNG  (Fig. 4 from any cells)

(`python -m roll_jax.analysis CMD ...` is the same.) `latent-vs-distance` and `occlusion`
analyse pretrained encoders: DIR = `roll-pretrain --task TASK --out DIR` (DIR/segmentation,
DIR/encoders, DIR/pretrain.json: the task and preset they were made with) or RUN = a
`train.py --out` directory (the segmentation and encoders it trained with, its config.json),
which is only read. They write to --out (default DIR/analysis); their JSON keys follow
docs/architecture.md ("Evaluation files"): `spearman_object`, `spearman_scene`;
`error_cm` = {"lstm_matching": [mean, std], "lstm": [...], "vae": [...]}. `CMD --help`
describes each command.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import sys

# Commands with their own parser: module, function (imported only to run them: their parsers
# are built before JAX loads).
DELEGATED = {"reward-probe": ("roll_jax.analysis.reward_probe", "main"),
             "diagnose": ("roll_jax.analysis.diagnose", "main"),
             "compare": ("roll_jax.analysis.compare", "main"),
             "policy-panel": ("roll_jax.analysis.compare", "panel_main"),
             "figure4": ("roll_jax.analysis.figure4", "main")}
HELP = {"reward-probe": "what runs' reward encoders measure: object vs hand distance",
        "diagnose": "a push task's encoders, reset and prior goals, before tuning",
        "compare": "two runs paired: learning curves, final policies on shared goals",
        "policy-panel": "goal images and each run's final frames from roll-evaluate outputs",
        "figure4": "paper Figure 4 and paired ROLL differences from cells run anywhere"}


def make_parser() -> argparse.ArgumentParser:
    from configs.encoders import HURDLE_TASKS, OCCLUSION_DROP
    from configs.train import PRESETS, TASKS

    p = argparse.ArgumentParser(prog="roll-analysis", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="cmd", required=True, metavar="CMD")
    a1 = sub.add_parser("latent-vs-distance", help="paper Figure 5")
    a1.add_argument("--task", default=None, metavar="TASK",
                    help=f"one of {', '.join(TASKS)} (default: the checkpoint's)")
    a1.add_argument("--n", type=int, default=500, help="observations (default 500)")
    a2 = sub.add_parser("occlusion", help="appendix A occlusion retrieval")
    a2.add_argument("--task", default=None, metavar="TASK",
                    help=f"a task with a hurdle path, one of {', '.join(HURDLE_TASKS)} "
                         "(default: the checkpoint's, else hurdle_top)")
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
        src = a.add_mutually_exclusive_group(required=True)
        src.add_argument("--ckpt", metavar="DIR",
                         help="a pretraining directory: roll-pretrain --out DIR")
        src.add_argument("--run", metavar="RUN",
                         help="a train.py --out directory: its segmentation and encoders, "
                              "its config (read only; give --out)")
        a.add_argument("--out", default=None, metavar="OUT",
                       help="output directory (default: DIR/analysis with --ckpt; outside "
                            "RUN, required, with --run)")
        a.add_argument("--preset", default=None, metavar="PRESET",
                       help=f"one of {', '.join(PRESETS)}: the preset the encoders were "
                            "pretrained with (default: the checkpoint's, from pretrain.json "
                            "or the run's config.json)")
        a.add_argument("--seed", type=int, default=0, help="PRNG seed (default 0)")
    for name, text in HELP.items():  # listed here, parsed by their own modules
        sub.add_parser(name, help=text, add_help=False)
    return p


def resolve(a, p) -> tuple[str, str]:
    """(the encoders' directory, the output directory); configs/ only, no JAX."""
    from configs.encoders import HURDLE_TASKS
    from configs.train import PRESETS, TASKS

    tasks = TASKS if a.cmd == "latent-vs-distance" else HURDLE_TASKS
    if a.task is not None and a.task not in tasks:
        p.error(f"unknown --task {a.task!r}; expected one of {', '.join(tasks)}")
    if a.preset is not None and a.preset not in PRESETS:
        p.error(f"unknown --preset {a.preset!r}; expected one of {', '.join(PRESETS)}")
    if a.run is not None:
        if not os.path.exists(os.path.join(a.run, "config.json")):
            p.error(f"--run {a.run} is not a train.py run directory (no config.json); a "
                    "pretraining directory is --ckpt")
        if a.out is None:
            p.error("--run needs --out (the run directory is only read)")
        run, out = os.path.realpath(a.run), os.path.realpath(a.out)
        if out == run or out.startswith(run + os.sep):
            p.error(f"--out {a.out} is inside the run directory {a.run}: the analyses write "
                    "nothing there")
        return a.run, a.out
    return a.ckpt, a.out or os.path.join(a.ckpt, "analysis")


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv and argv[0] in DELEGATED:
        module, func = DELEGATED[argv[0]]
        getattr(importlib.import_module(module), func)(argv[1:])
        return 0
    p = make_parser()
    a = p.parse_args(argv)
    ckpt, out = resolve(a, p)
    try:
        from roll_jax.analysis.checkpoints import checkpoint_preset, checkpoint_task

        if a.cmd == "latent-vs-distance":
            from roll_jax.analysis.fig5 import run_latent_vs_distance

            task = checkpoint_task(ckpt, a.task)
            res = run_latent_vs_distance(task, ckpt, out, a.n, a.seed, a.preset)
        else:
            from configs import presets
            from roll_jax.analysis.occlusion import HURDLE_TASKS, run_occlusion

            task = a.task
            if task is None:
                try:
                    task = checkpoint_task(ckpt)
                except ValueError:  # the directory does not say: the default task
                    task = "hurdle_top"
            if task not in HURDLE_TASKS:
                raise ValueError(f"{ckpt} is a {task} checkpoint; the occlusion analysis "
                                 f"needs a task with a hurdle path ({', '.join(HURDLE_TASKS)})")
            d = presets.get(checkpoint_preset(ckpt, task, a.preset)).for_task("occlusion", task)
            res = run_occlusion(ckpt, out, task,
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
