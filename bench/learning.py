"""Learning benchmark (issue 6, item 9a): can the RL stack learn puck pushing at all?

Mode `oracle` (this file's only mode so far): goal-conditioned SAC + HER on `puck_push` with the
*true* state instead of learned latents, which tests SAC (`roll_jax/sac.py`), the trajectory
replay buffer and its relabeling (`roll_jax/replay.py`, used as it is) and the MJX physics
together, in the structure the real training loop will have:

* observation = true hand xy + puck xy; goal = puck goal xy (env.sample_goal -> env.object_state);
  positions are shifted to the workspace centre and divided by `obs_scale` before entering the
  networks (the buffer stores metres);
* reward = -||puck' - goal||_2 in metres (the plain Euclidean distance, an oracle reward),
  recomputed from the relabeled batch (next_obs holds puck'); `--reward sq` uses replay.py's own
  -||puck' - goal||^2 instead;
* HER as Skew-Fit/ROLL: 20% rollout goals, 50% 'prior' goals = fresh goals drawn uniformly from
  the task's puck goal box (the oracle analogue of decoding a VAE-prior sample), 30% future
  achieved goals of the same episode;
* one jitted chunk `jax.jit(jax.vmap(chunk), donate_argnums=0)` over a leading seed axis:
  lax.scan over episodes of N parallel envs, each a lax.scan over env steps; after every
  vectorised env step `updates_per_step * N` SAC updates (i.e. `updates_per_step` per collected
  transition), skipped by lax.cond (unbatched predicate) before `learning_starts` env steps;
  uniform random actions before `learning_starts`, policy samples after;
* the replay buffer stores images too: here a dummy 1x1x3 image of zeros per step;
* evaluation after every chunk: deterministic policy (tanh of the mean) on `eval_goals` fresh test
  goals per seed, puck distance to the goal after the 50-step episode (env.goal_distance).

Prints one line per chunk, writes bench/results/learning_oracle.json (config, curve, wall time,
steps/s) and bench/results/learning_oracle.png.

    python bench/learning.py                       # oracle, CPU defaults (~10 min on 2 cores)
    python bench/learning.py --total-env-steps 2000 --out /tmp/l.json   # smoke run

A later `--mode roll` will reuse `run()` with the learned encoders in place of `oracle_obs`
and the latent reward in place of the oracle reward.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import platform
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
from flax import struct  # noqa: E402

import envs_mjx  # noqa: E402
from configs.sac import SACConfig  # noqa: E402
from roll_jax import replay  # noqa: E402
from roll_jax.sac import SACState, Transition, init_sac, sac_update, select_action  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RESULTS = os.path.join(ROOT, "bench", "results")
IMAGE_SHAPE = (1, 1, 3)  # dummy images: the oracle needs none, the buffer stores them anyway


@dataclasses.dataclass(frozen=True)
class BenchConfig:
    mode: str = "oracle"
    task: str = "puck_push"
    seeds: int = 1
    n_envs: int = 8
    total_env_steps: int = 50_000
    episodes_per_chunk: int = 5  # per env: a chunk is n_envs * horizon * this env steps
    eval_goals: int = 32  # per seed, fresh every evaluation
    reward: str = "l2"  # "l2": -||puck' - g|| (m); "sq": replay.py's -||puck' - g||^2 (m^2)
    obs_scale: float = 0.1  # network inputs = (position - workspace centre) / obs_scale
    target_distance: float = 0.03  # success: final puck distance <= 3 cm
    # CPU-sized SAC: Table 4 has (400, 300) and batch 1024; see notes.cpu_sizes in the output.
    sac: SACConfig = dataclasses.field(default_factory=lambda: SACConfig(
        hidden=(128, 128), batch_size=256, learning_starts=2_000, updates_per_step=2))

    def __post_init__(self):
        if self.mode != "oracle":
            raise ValueError(f"mode {self.mode!r} not implemented yet (only 'oracle')")
        if self.reward not in ("l2", "sq"):
            raise ValueError(f"reward must be 'l2' or 'sq', got {self.reward!r}")
        for name in ("seeds", "n_envs", "total_env_steps", "episodes_per_chunk", "eval_goals"):
            if getattr(self, name) <= 0:
                raise ValueError(f"BenchConfig.{name} must be positive, got {getattr(self, name)}")

    def chunk_env_steps(self, horizon: int) -> int:
        return self.n_envs * horizon * self.episodes_per_chunk

    def n_chunks(self, horizon: int) -> int:
        return -(-self.total_env_steps // self.chunk_env_steps(horizon))


@struct.dataclass
class TrainState:
    sac: SACState
    buffer: replay.ReplayBuffer
    key: jax.Array


# ----------------------------------------------------------------------------- oracle pieces

class Oracle:
    """State observations, goals and rewards for the oracle run of one push task."""

    def __init__(self, env, cfg: BenchConfig):
        spec = env.spec
        self.env, self.cfg = env, cfg
        self.goal_low = jnp.asarray(spec.object_goal_low, jnp.float32)
        self.goal_high = jnp.asarray(spec.object_goal_high, jnp.float32)
        self.centre = 0.5 * (self.goal_low + self.goal_high)
        self.obs_dim, self.goal_dim = 4, env.object_size

    def obs(self, state):
        """[4]: hand xy, puck xy (metres)."""
        return jnp.concatenate([self.env.hand_pos(state)[:2], self.env.object_state(state)])

    def achieved(self, obs):
        return obs[..., 2:4]

    def goal(self, key):
        """(goal xy, goal EnvState) from the task's goal space."""
        g = self.env.sample_goal(key)
        return self.env.object_state(g), g

    def prior_goals(self, key, n: int):
        """n goals uniform in the puck goal box (the same law as env.sample_goal's puck)."""
        u = jax.random.uniform(key, (n, self.goal_dim))
        return self.goal_low + (self.goal_high - self.goal_low) * u

    def norm_obs(self, obs):
        c = jnp.concatenate([self.centre, self.centre])
        return (obs - c) / self.cfg.obs_scale

    def norm_goal(self, g):
        return (g - self.centre) / self.cfg.obs_scale

    def prepare(self, batch: Transition) -> Transition:
        """Oracle reward from the relabeled batch, then network-scale inputs."""
        if self.cfg.reward == "l2":
            reward = -jnp.linalg.norm(self.achieved(batch.next_obs) - batch.goal, axis=-1)
        else:
            reward = batch.reward  # replay.py: -||goal_latents[t+1] - g||^2, same numbers here
        return batch.replace(obs=self.norm_obs(batch.obs), next_obs=self.norm_obs(batch.next_obs),
                             goal=self.norm_goal(batch.goal), reward=reward)

    def act(self, policy_params, obs, goal, key, deterministic=False):
        return select_action(policy_params, self.norm_obs(obs), self.norm_goal(goal), key,
                             deterministic)


# ----------------------------------------------------------------------------- train / eval

def make_fns(env, cfg: BenchConfig):
    oracle = Oracle(env, cfg)
    sc = cfg.sac
    n, horizon, a_dim = cfg.n_envs, env.horizon, env.action_size
    fracs = sc.goal_fracs
    n_updates = sc.updates_per_step * n  # per vectorised env step

    def init(key) -> TrainState:
        k_sac, key = jax.random.split(key)
        return TrainState(
            sac=init_sac(k_sac, oracle.obs_dim, oracle.goal_dim, a_dim, sc),
            buffer=replay.init_buffer(sc.replay_capacity(horizon), horizon, IMAGE_SHAPE, a_dim,
                                      oracle.obs_dim, oracle.goal_dim),
            key=key)

    def updates(sac, buffer, key):
        def one(i, c):
            s, m_sum = c
            k_batch, k_prior, k_upd = jax.random.split(jax.random.fold_in(key, i), 3)
            prior = oracle.prior_goals(k_prior, sc.batch_size)
            batch = replay.sample_transitions(buffer, k_batch, sc.batch_size, prior, fracs)
            s, m = sac_update(s, k_upd, oracle.prepare(batch), sc)
            m = {k: v.astype(jnp.float32) for k, v in m.items()}
            return s, jax.tree.map(jnp.add, m_sum, m)
        zero = {k: jnp.zeros((), jnp.float32) for k in _METRIC_KEYS}
        sac, m = jax.lax.fori_loop(0, n_updates, one, (sac, zero))
        return sac, {k: v / n_updates for k, v in m.items()}

    def episode(ts: TrainState, steps_before):
        """One episode of n envs with updates after every step; steps_before is unbatched."""
        key, k_reset, k_goal, k_steps = jax.random.split(ts.key, 4)
        states = jax.vmap(env.reset)(jax.random.split(k_reset, n))
        goals, _ = jax.vmap(oracle.goal)(jax.random.split(k_goal, n))
        obs0 = jax.vmap(oracle.obs)(states)

        def step(c, inp):
            sac, es, obs = c
            t, k = inp
            k_act, k_rand, k_upd = jax.random.split(k, 3)
            learning = steps_before + t * n >= sc.learning_starts  # unbatched: a real cond
            pi = jax.vmap(lambda o, g, kk: oracle.act(sac.policy_params, o, g, kk))(
                obs, goals, jax.random.split(k_act, n))
            rnd = jax.random.uniform(k_rand, (n, a_dim), minval=-1.0, maxval=1.0)
            a = jnp.where(learning, pi, rnd)
            es = jax.vmap(env.step)(es, a)
            obs = jax.vmap(oracle.obs)(es)
            sac, m = jax.lax.cond(learning, lambda: updates(sac, ts.buffer, k_upd),
                                  lambda: (sac, _no_update_metrics()))
            return (sac, es, obs), (a, obs, m, learning)

        (sac, _, _), (acts, obs, m, learned) = jax.lax.scan(
            step, (ts.sac, states, obs0), (jnp.arange(horizon), jax.random.split(k_steps, horizon)))
        m_finite = m["finite"]  # [T] mean over the step's updates: 1.0 iff all were finite
        obs_all = jnp.concatenate([obs0[None], obs], axis=0).swapaxes(0, 1)  # [n, T+1, 4]
        zeros_img = jnp.zeros((n, horizon + 1, *IMAGE_SHAPE), jnp.uint8)
        traj = replay.Trajectory(images=zeros_img, object_images=zeros_img,
                                 actions=acts.swapaxes(0, 1), obs_latents=obs_all,
                                 goal_latents=oracle.achieved(obs_all), rollout_goals=goals)
        buffer = replay.add_trajectories(ts.buffer, traj)
        # Note: the updates during this episode sample only completed episodes (as rlkit adds
        # whole paths to its buffer); this episode becomes visible from the next one on.
        final = jnp.linalg.norm(oracle.achieved(obs_all[:, -1]) - goals, axis=-1)
        n_learn = jnp.maximum(jnp.sum(learned), 1)
        # SAC metrics: means over this episode's updating steps (chunk reports its last episode).
        m = {k: jnp.sum(jnp.where(learned, v, 0.0)) / n_learn for k, v in m.items()}
        m["finite"] = jnp.min(jnp.where(learned, m_finite, 1.0))
        m["train_final_distance"] = jnp.mean(final)
        return TrainState(sac=sac, buffer=buffer, key=key), m

    def chunk(ts: TrainState, steps_before):
        def body(ts, e):
            return episode(ts, steps_before + e * n * horizon)
        ts, m = jax.lax.scan(body, ts, jnp.arange(cfg.episodes_per_chunk))
        return ts, jax.tree.map(lambda v: v[-1], m) | {
            "train_final_distance": jnp.mean(m["train_final_distance"])}

    def evaluate(policy_params, key):
        """(final, initial) puck distances [eval_goals] of the deterministic policy on fresh goals."""
        def one(k):
            k_reset, k_goal = jax.random.split(k)
            s = env.reset(k_reset)
            g, g_state = oracle.goal(k_goal)
            d0 = jnp.linalg.norm(env.object_state(s) - g)

            def step(s, _):
                a = oracle.act(policy_params, oracle.obs(s), g, None, deterministic=True)
                return env.step(s, a), None
            s, _ = jax.lax.scan(step, s, None, length=horizon)
            return env.goal_distance(s, g_state), d0
        return jax.vmap(one)(jax.random.split(key, cfg.eval_goals))

    return init, chunk, evaluate


_METRIC_KEYS = ("q_loss", "policy_loss", "alpha", "alpha_loss", "q_mean", "q_target_mean",
                "entropy", "q_grad_norm", "policy_grad_norm", "finite")


def _no_update_metrics():
    """Metrics of a step without SAC updates (warm-up): zeros, and finite = 1."""
    return {k: jnp.asarray(1.0 if k == "finite" else 0.0, jnp.float32) for k in _METRIC_KEYS}


# ----------------------------------------------------------------------------- driver

def run(cfg: BenchConfig, seed: int = 0, log=print) -> dict:
    env = envs_mjx.make(cfg.task)
    horizon = env.horizon
    if cfg.sac.learning_starts < cfg.n_envs * horizon:
        raise ValueError("learning_starts must cover at least one episode of every env "
                         f"({cfg.n_envs * horizon} steps), got {cfg.sac.learning_starts}")
    init, chunk, evaluate = make_fns(env, cfg)
    t_start = time.perf_counter()
    keys = jax.random.split(jax.random.PRNGKey(seed), cfg.seeds + 1)
    ts = jax.jit(jax.vmap(init))(keys[1:])
    eval_key = jax.random.fold_in(keys[0], 1)
    steps0 = jnp.zeros((), jnp.int32)

    chunk_fn = jax.jit(jax.vmap(chunk, in_axes=(0, None)), donate_argnums=0)
    eval_fn = jax.jit(jax.vmap(evaluate, in_axes=(0, None)))
    t0 = time.perf_counter()
    chunk_c = chunk_fn.lower(ts, steps0).compile()
    compile_chunk = time.perf_counter() - t0
    t0 = time.perf_counter()
    eval_c = eval_fn.lower(ts.sac.policy_params, eval_key).compile()
    compile_eval = time.perf_counter() - t0
    log(f"compile: chunk {compile_chunk:.1f} s, eval {compile_eval:.1f} s")

    per_chunk = cfg.chunk_env_steps(horizon) * cfg.seeds
    curve, train_s, eval_s = [], 0.0, 0.0
    learn_steps, learn_s, warm_steps, warm_s = 0, 0.0, 0, 0.0

    def do_eval(env_steps, m=None, chunk_s=None):
        nonlocal eval_s
        t0 = time.perf_counter()
        d, d0 = jax.device_get(eval_c(ts.sac.policy_params, jax.random.fold_in(eval_key, env_steps)))
        eval_s += time.perf_counter() - t0
        row = {"env_steps": int(env_steps), "final_distance_median": float(np.median(d)),
               "final_distance_mean": float(np.mean(d)),
               "success_rate": float(np.mean(d <= cfg.target_distance)),
               "initial_distance_median": float(np.median(d0)),
               "wall_s": time.perf_counter() - t_start}
        if m is not None:
            row |= {k: float(np.mean(v)) for k, v in m.items()}
            row["chunk_steps_per_s"] = per_chunk / chunk_s
        curve.append(row)
        extra = "" if m is None else (
            f" | train final {row['train_final_distance'] * 100:5.2f} cm, alpha {row['alpha']:.2e},"
            f" q {row['q_mean']:7.3f}, q_loss {row['q_loss']:.2e}, {row['chunk_steps_per_s']:.0f} steps/s")
        log(f"env steps {env_steps:6d} (per seed) | eval final distance median "
            f"{row['final_distance_median'] * 100:5.2f} cm, mean {row['final_distance_mean'] * 100:5.2f} cm, "
            f"success {row['success_rate']:.2f} (start {row['initial_distance_median'] * 100:.1f} cm)"
            + extra)
        return row

    do_eval(0)
    env_steps = 0
    for _ in range(cfg.n_chunks(horizon)):
        t0 = time.perf_counter()
        ts, m = chunk_c(ts, jnp.asarray(env_steps, jnp.int32))
        m = jax.device_get(m)
        dt = time.perf_counter() - t0
        train_s += dt
        if env_steps >= cfg.sac.learning_starts:
            learn_steps, learn_s = learn_steps + per_chunk, learn_s + dt
        elif env_steps + cfg.chunk_env_steps(horizon) <= cfg.sac.learning_starts:
            warm_steps, warm_s = warm_steps + per_chunk, warm_s + dt
        env_steps += cfg.chunk_env_steps(horizon)
        if not np.all(m["finite"] >= 1.0):
            log("non-finite SAC loss or gradient: stopping")
            do_eval(env_steps, m, dt)
            break
        do_eval(env_steps, m, dt)

    wall = time.perf_counter() - t_start
    reached = [r["env_steps"] for r in curve if r["final_distance_median"] <= cfg.target_distance]
    return {
        "curve": curve,
        "wall_time_s": wall,
        "compile_s": {"chunk": compile_chunk, "eval": compile_eval},
        "train_s": train_s, "eval_s": eval_s,
        # All chunks (random warm-up included); then only chunks with SAC updates throughout.
        "train_env_steps_per_s": env_steps * cfg.seeds / train_s,
        "learning_env_steps_per_s": learn_steps / learn_s if learn_s else None,
        "sac_updates_per_s": learn_steps * cfg.sac.updates_per_step / learn_s if learn_s else None,
        "warmup_env_steps_per_s": warm_steps / warm_s if warm_s else None,
        "env_steps": env_steps,
        "final": curve[-1],
        "best_median": min(r["final_distance_median"] for r in curve),
        "first_env_steps_median_le_target": reached[0] if reached else None,
        "reached_target": bool(curve[-1]["final_distance_median"] <= cfg.target_distance),
    }


def plot(result: dict, cfg: BenchConfig, path: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    c = result["curve"]
    x = [r["env_steps"] for r in c]
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot(x, [100 * r["final_distance_median"] for r in c], "o-", label="eval median")
    ax.plot(x, [100 * r["final_distance_mean"] for r in c], "s--", label="eval mean", alpha=0.7)
    tr = [(r["env_steps"], 100 * r["train_final_distance"]) for r in c if "train_final_distance" in r]
    if tr:
        ax.plot(*zip(*tr), ":", color="grey", label="training episodes of the chunk (stochastic)")
    ax.plot(x, [100 * r["initial_distance_median"] for r in c], color="grey", lw=0.8, ls="--",
            label="puck untouched (test goals' initial median)")
    ax.axhline(100 * cfg.target_distance, color="red", lw=0.8, label="3 cm target")
    ax.axvline(cfg.sac.learning_starts, color="black", lw=0.6, ls=":", label="learning starts")
    ax.set_xlabel("env steps (per seed)")
    ax.set_ylabel("final puck distance (cm)")
    ax.set_title(f"{cfg.task}: oracle SAC+HER (state obs), {cfg.n_envs} envs, "
                 f"{cfg.eval_goals} test goals", fontsize=9)
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def run_roll(args) -> dict:
    """Item 9b: ROLL itself (train.run, the compiled loop) on `--task`; the median final object
    distance over seeds against env steps -> JSON + PNG beside it."""
    import shutil

    from roll_jax import train

    sets = list(args.set)
    if not any(x.startswith("total_env_steps=") for x in sets):
        sets.append(f"total_env_steps={args.total_env_steps}")
    cfg = train.build_config(args.task, "roll", args.preset, seeds=args.seeds, overrides=sets)
    print(f"jax {jax.__version__} on {jax.devices()[0]} ({os.cpu_count()} CPUs, load "
          f"{os.getloadavg()[0]:.1f}); ROLL {args.task} preset {args.preset}, {cfg.seeds} seeds, "
          f"{cfg.total_env_steps} env steps per seed", flush=True)
    load0 = os.getloadavg()[0]
    t0 = time.perf_counter()
    rows = train.run(cfg, args.run_dir, seg_ckpt=args.seg_ckpt, enc_ckpt=args.enc_ckpt,
                     seed=args.seed, progress=True)
    wall = time.perf_counter() - t0
    steps, med, q25, q75 = train.seed_quantiles(rows)
    out = {"mode": "roll", "task": args.task, "preset": args.preset, "seeds": cfg.seeds,
           "total_env_steps": cfg.total_env_steps, "overrides": sets,
           "seg_ckpt": args.seg_ckpt, "enc_ckpt": args.enc_ckpt,
           "curve": {"env_steps": steps.tolist(), "median_final_distance": med.tolist(),
                     "q25": q25.tolist(), "q75": q75.tolist()},
           "wall_s_incl_setup_and_compile": round(wall, 1),
           "device": str(jax.devices()[0]), "jax": jax.__version__,
           "load_avg_start_end": [round(load0, 2), round(os.getloadavg()[0], 2)]}
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    with open(args.out, "w") as f:
        json.dump(out, f, indent=2)
    shutil.copy(os.path.join(args.run_dir, "plots", "learning_curve.png"),
                os.path.splitext(args.out)[0] + ".png")
    for s_, m_, a_, b_ in zip(steps, med, q25, q75):
        print(f"env steps {int(s_):7d}: median final distance {m_ * 100:.2f} cm "
              f"(25-75%: {a_ * 100:.2f}-{b_ * 100:.2f})")
    print(f"wrote {args.out} ({wall:.0f} s)")
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    d = BenchConfig()
    p.add_argument("--mode", default="oracle", choices=["oracle", "roll"],
                   help="roll: the real ROLL loop (train.run) with --preset/--seg-ckpt/--set")
    p.add_argument("--preset", default="smoke", choices=["smoke", "paper"], help="roll mode only")
    p.add_argument("--seg-ckpt", default=None, help="roll mode: a fitted segmentation")
    p.add_argument("--enc-ckpt", default=None, help="roll mode: pretrained encoders")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="roll mode: config overrides as in train.py")
    p.add_argument("--run-dir", default=os.path.join(ROOT, "runs", "learning_roll"),
                   help="roll mode: the training run's output folder")
    p.add_argument("--task", default=d.task)
    p.add_argument("--seeds", type=int, default=d.seeds)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--n-envs", type=int, default=d.n_envs)
    p.add_argument("--total-env-steps", type=int, default=d.total_env_steps)
    p.add_argument("--episodes-per-chunk", type=int, default=d.episodes_per_chunk)
    p.add_argument("--eval-goals", type=int, default=d.eval_goals)
    p.add_argument("--reward", default=d.reward, choices=["l2", "sq"])
    p.add_argument("--obs-scale", type=float, default=d.obs_scale)
    p.add_argument("--hidden", type=int, nargs="+", default=list(d.sac.hidden))
    p.add_argument("--batch-size", type=int, default=d.sac.batch_size)
    p.add_argument("--updates-per-step", type=int, default=d.sac.updates_per_step,
                   help="SAC updates per collected transition (Table 4: 2)")
    p.add_argument("--learning-starts", type=int, default=d.sac.learning_starts)
    p.add_argument("--reward-scale", type=float, default=d.sac.reward_scale)
    p.add_argument("--tau", type=float, default=d.sac.tau)
    p.add_argument("--out", default=None,
                   help="JSON path (default bench/results/learning_<mode>.json)")
    p.add_argument("--no-cache", action="store_true", help="no persistent compilation cache")
    args = p.parse_args()
    args.out = args.out or os.path.join(RESULTS, f"learning_{args.mode}.json")
    if not args.no_cache:
        jax.config.update("jax_compilation_cache_dir", os.path.join(ROOT, ".jax_cache"))
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)

    if args.mode == "roll":
        run_roll(args)
        return
    sac = dataclasses.replace(d.sac, hidden=tuple(args.hidden), batch_size=args.batch_size,
                              updates_per_step=args.updates_per_step,
                              learning_starts=args.learning_starts, reward_scale=args.reward_scale,
                              tau=args.tau)
    cfg = BenchConfig(mode=args.mode, task=args.task, seeds=args.seeds, n_envs=args.n_envs,
                      total_env_steps=args.total_env_steps,
                      episodes_per_chunk=args.episodes_per_chunk, eval_goals=args.eval_goals,
                      reward=args.reward, obs_scale=args.obs_scale, sac=sac)
    print(f"jax {jax.__version__} on {jax.devices()[0]} ({os.cpu_count()} CPUs, load "
          f"{os.getloadavg()[0]:.1f}); {cfg}", flush=True)
    load0 = os.getloadavg()[0]
    result = run(cfg, args.seed, log=lambda s: print(s, flush=True))

    cfg_json = dataclasses.asdict(cfg)
    out = {
        "mode": cfg.mode,
        "config": cfg_json,
        "notes": {
            "observation": "true hand xy + puck xy (metres), networks see (p - goal-box centre) / obs_scale",
            "goal": "puck goal xy from env.sample_goal + env.object_state",
            "reward": ("-||puck' - goal||_2 in metres (Euclidean; recomputed from the relabeled batch)"
                       if cfg.reward == "l2" else "-||puck' - goal||^2 in m^2 (replay.py's form)"),
            "her": "fractions (rollout, prior, future) = "
                   f"{cfg.sac.goal_fracs}; prior goals uniform in the puck goal box",
            "cpu_sizes": "Table 4 uses hidden (400, 300), batch 1024, learning_starts 10k; "
                         f"this CPU run uses hidden {cfg.sac.hidden}, batch {cfg.sac.batch_size}, "
                         f"learning_starts {cfg.sac.learning_starts} (uniform random actions before), "
                         f"{cfg.sac.updates_per_step} updates per collected transition "
                         f"({cfg.sac.updates_per_step * cfg.n_envs} per vectorised step of "
                         f"{cfg.n_envs} envs)",
            "evaluation": f"deterministic policy, {cfg.eval_goals} fresh goals per evaluation and "
                          "seed, final puck distance after the 50-step episode (env.goal_distance)",
        },
        "seed": args.seed,
        "load_average_at_start": load0,
        "command": "python bench/learning.py " + " ".join(sys.argv[1:]),
        "load_average_at_end": os.getloadavg()[0],
        "device": str(jax.devices()[0]), "backend": jax.default_backend(),
        "cpu_count": os.cpu_count(), "machine": platform.machine(), "jax": jax.__version__,
        **result,
    }
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    with open(args.out, "w") as f:
        json.dump(out, f, indent=2)
    png = os.path.splitext(args.out)[0] + ".png"
    plot(result, cfg, png)
    f = result["final"]
    print(f"final (env steps {f['env_steps']}): median {f['final_distance_median'] * 100:.2f} cm, "
          f"mean {f['final_distance_mean'] * 100:.2f} cm, success {f['success_rate']:.2f}; "
          f"best median {result['best_median'] * 100:.2f} cm; target <= "
          f"{cfg.target_distance * 100:.0f} cm {'REACHED' if result['reached_target'] else 'NOT reached'}; "
          f"wall {result['wall_time_s']:.0f} s (compile {sum(result['compile_s'].values()):.0f} s); "
          f"env steps/s: {result['warmup_env_steps_per_s'] or 0:.0f} random warm-up, "
          f"{result['learning_env_steps_per_s'] or 0:.0f} with {cfg.sac.updates_per_step} SAC "
          f"updates per step ({result['sac_updates_per_s'] or 0:.0f} updates/s)")
    print(f"wrote {args.out} and {png}")


if __name__ == "__main__":
    main()
