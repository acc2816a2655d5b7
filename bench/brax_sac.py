"""A trainer nobody here wrote, on the scenes: Brax's SAC on puck_push from state observations.

The env is `envs_mjx.registry.load("PuckPush", obs_type="state", done_at_horizon=False)`
(hand xyz, puck xy, goal xy; reward -distance of the puck to the goal in metres), wrapped by
`envs_mjx.brax_training.wrap_for_brax_training` (Brax's VmapWrapper and EpisodeWrapper, a full
reset with a new goal on done) and trained by `brax.training.agents.sac.train` unchanged. Each
evaluation (Brax's evaluator: `--eval-envs` episodes, deterministic policy) reports the puck's
final distance to its goal; the curve, the wall time and the env steps/s go to
bench/results/brax_sac.json after every evaluation (a cut-off run keeps its figures) and the
curve to docs/images/brax_sac_puck_push.png.

    python -m bench brax_sac                          # 100k env steps (the documented run)
    python -m bench brax_sac --steps 4000 --evals 2   # a smoke of the same path

Needs `pip install -e ".[brax]"`.
"""

from __future__ import annotations

import argparse
import os
import time

from bench.common import REPO, machine_info, result_path, write_result


def make_env(task: str = "PuckPush"):
    from envs_mjx import registry

    return registry.load(task, obs_type="state", done_at_horizon=False)


def train(args, on_eval):
    """Brax SAC with the arguments of the command; `on_eval(env_steps, metrics)` after each
    evaluation. Returns the trained (make_policy, params)."""
    from brax.training.agents.sac import train as sac

    from envs_mjx.brax_training import wrap_for_brax_training

    env = make_env(args.task)
    make_policy, params, _ = sac.train(
        environment=env, wrap_env_fn=wrap_for_brax_training,
        num_timesteps=args.steps, episode_length=env.episode_length,
        num_envs=args.envs, num_eval_envs=args.eval_envs, num_evals=args.evals,
        batch_size=args.batch, grad_updates_per_step=args.updates,
        learning_rate=args.lr, discounting=args.discount, reward_scaling=args.reward_scale,
        min_replay_size=args.min_replay, max_replay_size=args.steps,
        normalize_observations=True, deterministic_eval=True, seed=args.seed,
        progress_fn=on_eval)
    return make_policy, params


def plot(curve, path: str, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5, 3.2))
    ax.plot([c["env_steps"] / 1000 for c in curve], [100 * c["final_distance_m"] for c in curve],
            "o-")
    ax.set_xlabel("env steps (thousands)")
    ax.set_ylabel("final puck-goal distance (cm)")
    ax.set_title(title, fontsize=9)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    os.makedirs(os.path.dirname(path), exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None) -> None:
    p = argparse.ArgumentParser(prog="python -m bench brax_sac", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--task", default="PuckPush", help="registry name of the task")
    p.add_argument("--steps", type=int, default=100_000, help="env steps of training")
    p.add_argument("--envs", type=int, default=32, help="parallel training envs")
    p.add_argument("--eval-envs", type=int, default=64, help="episodes per evaluation")
    p.add_argument("--evals", type=int, default=11, help="evaluations, the first at step 0")
    p.add_argument("--batch", type=int, default=256, help="SAC batch size")
    p.add_argument("--updates", type=int, default=16,
                   help="gradient updates per vectorised env step (of --envs env steps)")
    p.add_argument("--lr", type=float, default=3e-4, help="learning rate")
    p.add_argument("--discount", type=float, default=0.97, help="discount")
    p.add_argument("--reward-scale", type=float, default=10.0,
                   help="reward multiplier (rewards are minus metres)")
    p.add_argument("--min-replay", type=int, default=2048, help="env steps before learning")
    p.add_argument("--seed", type=int, default=0, help="PRNG seed")
    p.add_argument("--out", default=result_path("brax_sac"), help="result file")
    p.add_argument("--png", default=os.path.join(REPO, "docs", "images", "brax_sac_puck_push.png"),
                   help="learning-curve figure ('' for none)")
    args = p.parse_args(argv)
    argv = list(argv) if argv is not None else None

    machine = machine_info()
    t0 = time.perf_counter()
    curve: list[dict] = []

    def figures():
        first = curve[0]["final_distance_m"] if curve else None
        last = curve[-1]["final_distance_m"] if curve else None
        # steps/s between the second and the last evaluation: the first interval holds the
        # compiles of Brax's training epoch
        timed = curve[1:] if len(curve) > 2 else []
        trained_s = timed[-1]["wall_s"] - timed[0]["wall_s"] if timed else None
        return {"task": args.task, "obs_type": "state", "trainer": "brax.training.agents.sac",
                "hyperparameters": {k: v for k, v in vars(args).items()
                                    if k not in ("out", "png")},
                "curve": curve, "start_final_distance_m": first, "final_distance_m": last,
                "ratio_to_start": (last / first) if curve and first else None,
                "wall_s": time.perf_counter() - t0,
                "env_steps_per_s_training": ((timed[-1]["env_steps"] - timed[0]["env_steps"])
                                             / trained_s) if trained_s else None,
                "first_interval_s_with_compiles": (curve[1]["wall_s"] - curve[0]["wall_s"])
                if len(curve) > 1 else None}

    def on_eval(step, metrics):
        dist = float(metrics["eval/episode_final_goal_distance"])
        curve.append({"env_steps": int(step), "final_distance_m": dist,
                      "mean_distance_m": float(metrics["eval/episode_goal_distance"])
                      / make_env(args.task).episode_length,
                      "wall_s": time.perf_counter() - t0})
        print(f"{int(step):>8d} env steps  final distance {100 * dist:5.2f} cm  "
              f"({curve[-1]['wall_s']:.0f} s)", flush=True)
        write_result("brax_sac", figures(), machine, argv, path=args.out)

    train(args, on_eval)
    write_result("brax_sac", figures(), machine, argv, path=args.out)
    if args.png:
        plot(curve, args.png, f"Brax SAC, {args.task} (state obs), seed {args.seed}")


if __name__ == "__main__":
    main()
