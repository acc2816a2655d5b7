"""Training-loop benchmark: env steps/s of the compiled ROLL chunk and where its time goes.

1. The whole chunk: `loop.compile_chunk` (jit of `loop.make_chunk` over the seeds, vmapped or,
   with --seed-batch (auto: 1 on CPU), mapped; state donated: the code path `train.py` runs)
   for each --seeds count, lowered and compiled ahead of time (compile time reported apart),
   then --chunks chunks; the first is a warm-up, the second onwards are timed (steady state).
   env steps/s = seeds x epoch_env_steps / chunk time. Every chunk timed here evaluates (its
   test envs step beside the training envs), as train.py's every `eval_every_epochs`-th one
   does; `sac_share_in_chunk` (bench/roofline.py --chunk) instead times one refresh cycle of
   plans with train.py's schedule of its two programs, on a full buffer.
2. Its parts, each its own jitted function over the same seeds and at the sizes one chunk uses,
   timed after a warm-up call:
     sim       episodes x horizon steps of vmap(env.step) (plus env.reset_episode per episode),
               random actions, in a lax.scan;
     render    env.render of the same poses: episodes x (horizon + 1) frames per env;
     segment   `pipeline.segment` (+ the segmented image) of those frames;
     encoders  scene-VAE means per step (batch n_envs, in a scan, as the policy's observation)
               and of every stored frame, object-VAE means of the segmented frames, the LSTM over
               each episode and the episode's prior goal (object-VAE prior -> one LSTM step);
     log_p     Skew-Fit's importance-sampled log p(x) of every stored frame under the scene-VAE
               (`skewfit.frame_log_p`, skew_num_latents decodes per frame);
     policy    the acting policy (sac.select_action, batch n_envs) per step;
     SAC       `loop.sac_updates`: epoch_env_steps x updates_per_step updates at the config's
               batch size on the replay buffer the timed chunks filled;
     lstm      --lstm-batches online LSTM batches on that buffer and the goal-latent refresh
               (nothing with --lstm-batches 0);
   the shares are of the sum of these parts. "collect" (`collect.collect_episode` per episode,
   the chunk's collection phase as one function, without the replay write) is timed too,
   for comparison (--no-collect skips it).

Networks are the --preset's (paper: SAC 400-300 at batch 1024, the paper's VAEs, U-Net and
LSTM); only the env steps per chunk (--epoch-env-steps, --n-envs) and the replay capacity
(--replay-size; SAC samples gather from it, so its size does not change the speed) are cut for
the CPU. The frozen segmentation (U-Net; MOG2 fitted on a few random frames) and the
encoders are freshly initialised with random weights: throughput does not depend on training
them, so no segmentation fitting or pre-training runs (the MOG2 model so fitted is, like the
scenes' fitted backgrounds, one whose lr-0 step changes nothing, so `mog2.foreground` takes
its short path as in a run). The chunk plan is the steady state after
`learning_starts`: the policy acts and SAC learns; scheduled scene-VAE / LSTM training is off by
default (--vae-batches / --lstm-batches switch it on; the compiled chunk holds those branches
either way).

    python -m bench chunk [--task puck_push] [--seeds 1 6] [--preset paper]
        [--epoch-env-steps 500] [--n-envs 10] [--chunks 3]
    # on a 2-core CPU (~14 min):
    python -m bench chunk --n-envs 1 --epoch-env-steps 50 --chunks 3 --reps 1 \
        --replay-size 10000 --no-collect

Writes bench/results/chunk.json (sizes, figures).
"""
from __future__ import annotations

import argparse
import dataclasses
import os
import statistics
import time

import jax
import jax.numpy as jnp

import envs_mjx
from bench.common import machine_info, result_path, write_result
from configs.presets import PRESETS
from configs.train import make_config
from roll_jax.agents import her, sac, skewfit
from roll_jax.encoders import models, steps
from roll_jax.encoders.goal_encoding import Frozen, goal_encoder
from roll_jax.segmentation import mog2, pipeline, unet
from roll_jax.training import loop, online, sharding
from roll_jax.training.collect import ChunkInputs, Collector, collect_episode
from roll_jax.training.state import ChunkPlan, init_state, lstm_params_of, plan_chunk
PARTS = ("sim", "render", "segment", "encoders", "log_p", "policy", "sac", "lstm")


# ----------------------------------------------------------------------------- helpers

def _block(x):
    return jax.block_until_ready(x)


def _compile(fn, *args):
    """AOT lower + compile of a jitted fn -> (compiled, lower_s, compile_s)."""
    t0 = time.perf_counter()
    lowered = fn.lower(*args)
    t1 = time.perf_counter()
    compiled = lowered.compile()
    t2 = time.perf_counter()
    return compiled, t1 - t0, t2 - t1


def _call(fn, *args):
    """(output, wall seconds, process CPU seconds: all threads of this process) of one call."""
    w0, c0 = time.perf_counter(), time.process_time()
    out = _block(fn(*args))
    return out, time.perf_counter() - w0, time.process_time() - c0


def _time_part(name: str, fn, args, reps: int, min_time: float = 1.0) -> dict:
    """Compile, one warm-up call, then at least `reps` timed calls (more, up to 20, until
    `min_time` seconds were timed): median and min wall seconds, median CPU seconds."""
    compiled, lower_s, compile_s = _compile(fn, *args)
    out, first, _ = _call(compiled, *args)
    walls, cpus = [], []
    while len(walls) < reps or (sum(walls) < min_time and len(walls) < 20):
        out, w, c = _call(compiled, *args)
        walls.append(w)
        cpus.append(c)
    res = {"lower_s": lower_s, "compile_s": compile_s, "first_call_s": first,
           "times_s": walls, "median_s": statistics.median(walls), "min_s": min(walls),
           "cpu_times_s": cpus, "cpu_median_s": statistics.median(cpus)}
    print(f"  {name:9s} compile {compile_s:6.1f} s (trace+lower {lower_s:5.1f} s)  "
          f"wall median {res['median_s']:8.3f} s  min {res['min_s']:8.3f} s  "
          f"cpu median {res['cpu_median_s']:8.3f} s  ({len(walls)} calls)", flush=True)
    return res, out


# ----------------------------------------------------------------------------- setup

def make_cfg(a, seeds: int, eval_every_epochs: int | None = 1):
    """The benchmark's config: the preset's, learning from the first chunk (the timed plan is
    the steady state anyway), evaluating every `eval_every_epochs` (None: the preset's)."""
    base = make_config(a.task, "roll", a.preset)
    sac_cfg = dataclasses.replace(base.sac, learning_starts=0, replay_size=(
        base.sac.replay_size if a.replay_size is None else a.replay_size))
    return make_config(a.task, "roll", a.preset, seeds=seeds, n_envs=a.n_envs,
                       epoch_env_steps=a.epoch_env_steps,
                       eval_every_epochs=eval_every_epochs or base.eval_every_epochs,
                       total_env_steps=a.epoch_env_steps * a.chunks, sac=sac_cfg)


def fresh_frozen_and_pretrained(cfg, key):
    """Random-weight stand-ins for the fitted segmentation and pre-trained encoders (same
    shapes and sizes; speed does not depend on the weights)."""
    enc = goal_encoder(cfg)
    k_bg, k_unet, k_scene, k_obj, k_lstm = jax.random.split(key, 5)
    h, w, c = cfg.scene.image_shape
    scfg = cfg.segmentation
    frames = jax.random.randint(k_bg, (50, h, w, c), 0, 256).astype(jnp.uint8)
    bg = mog2.init(h, w, c, history=scfg.n_frames, var_threshold=scfg.var_threshold,
                   detect_shadows=scfg.detect_shadows, n_mixtures=scfg.n_mixtures)
    bg, _ = mog2.apply_video(bg, frames, learning_rate=-1.0)
    seg = pipeline.SegParams(background=bg, unet=unet.init_unet(k_unet, scfg.unet_features, h, w),
                             robot_threshold=jnp.float32(scfg.robot_threshold))
    scene_vae = steps.init_vae(k_scene, cfg.scene)
    object_vae = steps.init_vae(k_obj, enc.object_cfg)
    lstm = steps.init_lstm(k_lstm, cfg.lstm, enc.frame_dim) if enc.lstm else None
    return Frozen(seg=seg, object_vae=object_vae.params), scene_vae, lstm


def _sac_share(with_sac: float, without_sac: float, n_updates: int) -> dict:
    sac_s = with_sac - without_sac
    return {"chunk_s": with_sac, "chunk_without_sac_s": without_sac, "sac_s": sac_s,
            "sac_updates": n_updates, "sac_ms_per_update": 1e3 * sac_s / n_updates,
            "chunk_over_sac": with_sac / sac_s if sac_s > 0 else float("inf")}


def steady_chunk_inputs(task: str, preset: str, first_epoch: int = 20, seeds: int = 1,
                        replay_size: int | None = None, full_buffer: bool = True):
    """What the chunks of `train.py --preset PRESET` are timed on: (cfg, env, frozen,
    new_state, plans). `new_state()` gives the same fresh seeds every call (the chunk donates
    its state); `plans` are one refresh cycle of steady-state (epoch, plan) from `first_epoch`
    on, and `evaluates(epoch)` says which of train.py's two chunks runs it (`chunk_programs`).
    `full_buffer`: the replay buffer counts as full (its initial contents), as in a run that
    has collected its capacity, so that the goal-latent refresh covers every stored episode;
    otherwise it starts empty and the timed chunks fill a few slots."""
    base = make_config(task, "roll", preset)
    # A run as long as the epochs timed (the evaluation schedule must fit in it).
    a = argparse.Namespace(task=task, preset=preset, replay_size=replay_size,
                           chunks=first_epoch + base.refresh_every_epochs, n_envs=None,
                           epoch_env_steps=None)
    a.n_envs, a.epoch_env_steps = base.n_envs, base.epoch_env_steps
    cfg = make_cfg(a, seeds, eval_every_epochs=None)
    env = envs_mjx.make(task)
    k_fz, k_init = jax.random.split(jax.random.PRNGKey(0))
    frozen, scene_vae, lstm = fresh_frozen_and_pretrained(cfg, k_fz)

    def init_one(k):
        st = init_state(k, cfg, env, scene_vae, lstm)
        if full_buffer:
            st = st.replace(buffer=st.buffer.replace(size=jnp.int32(st.buffer.capacity)))
        return st

    init = jax.jit(jax.vmap(init_one))
    plans = [(e, plan_chunk(cfg, e))
             for e in range(first_epoch, first_epoch + cfg.refresh_every_epochs)]
    return cfg, env, frozen, lambda: init(jax.random.split(k_init, seeds)), plans


def evaluates(cfg, epoch: int) -> bool:
    """Whether train.py runs `epoch` with the chunk that also evaluates (test envs in the
    collection batch) or with the one that does not."""
    return epoch % cfg.eval_every_epochs == 0


def _plan_of(cfg, plans, ev: bool):
    """The first of `plans` that the chunk with evaluate == `ev` runs."""
    return next(pl for e, pl in plans if evaluates(cfg, e) == ev)


def chunk_programs(cfg, env, frozen, state, plans, seeds: int = 1, make=None) -> dict:
    """{evaluate: (compiled chunk, lower_s, compile_s)} for the chunks `plans` use, as
    train.py builds them (`loop.compile_chunk`; `make(evaluate)` -> a jitted chunk instead),
    lowered and compiled ahead of time (the state is only read for its shapes)."""
    out = {}
    for ev in sorted({evaluates(cfg, e) for e, _ in plans}, reverse=True):
        fn = (make(ev) if make is not None else
              loop.compile_chunk(cfg, env, 1, sharding.resolve_seed_batch("auto", seeds),
                                 evaluate=ev))
        out[ev] = _compile(fn, state, frozen, _plan_of(cfg, plans, ev))
    return out


def warm_up(cfg, programs: dict, state, frozen, plans):
    """One call of each of `chunk_programs`' programs, the state passed on: (state,
    {evaluate: wall seconds of its first call})."""
    firsts = {}
    for ev, (compiled, _, _) in programs.items():
        (state, _), firsts[ev], _ = _call(compiled, state, frozen, _plan_of(cfg, plans, ev))
    return state, firsts


def sac_share_in_chunk(task: str, preset: str, first_epoch: int = 20, seeds: int = 1,
                       replay_size: int | None = None, rounds: int = 1,
                       yardsticks=None, full_buffer: bool = True) -> dict:
    """The chunks `train.py --preset PRESET` compiles (its schedules; its replay size unless
    `replay_size` is given), timed over `rounds` refresh cycles of steady-state plans (epochs
    `first_epoch` onwards: LSTM rounds, cached-latent refreshes and evaluations as a run has
    them, each plan on the program train.py gives it), each plan run with its SAC on and off
    back to back (the order flipped every other pair): the
    difference is the cost of the SAC updates inside the chunk (HER sampling, prior goals,
    gathers included).

    `yardsticks`: a function -> {name: ms per update} (e.g. the standalone update), called
    after each pair, so that each pair's in-chunk cost has yardsticks timed beside it on this
    drifting machine; the result then holds every pair's ratios and their medians."""
    cfg, env, frozen, new_state, plans = steady_chunk_inputs(task, preset, first_epoch, seeds,
                                                             replay_size, full_buffer)
    programs = chunk_programs(cfg, env, frozen, new_state(), plans, seeds)
    for ev, (_, lower_s, compile_s) in programs.items():
        print(f"  {task} {preset} chunk{' (evaluating)' if ev else ''}: trace+lower "
              f"{lower_s:.1f} s, compile {compile_s:.1f} s", flush=True)
    state, firsts = warm_up(cfg, programs, new_state(), frozen, plans)
    n_updates = cfg.epoch_env_steps * cfg.sac.updates_per_step
    walls = {"on": [], "off": []}
    pairs = []
    for i, (epoch, pl) in enumerate(plans * rounds):
        compiled = programs[evaluates(cfg, epoch)][0]
        for name in (("on", "off") if i % 2 == 0 else ("off", "on")):
            (state, _), w, _ = _call(compiled, state, frozen,
                                     pl if name == "on" else pl.replace(learn=jnp.bool_(False)))
            walls[name].append(w)
        pair = {"epoch": epoch, "evaluates": evaluates(cfg, epoch),
                "sac_ms_per_update": 1e3 * (walls["on"][-1] - walls["off"][-1]) / n_updates}
        if yardsticks is not None:
            pair["yardsticks_ms"] = yardsticks()
            pair["over"] = {k: pair["sac_ms_per_update"] / v
                            for k, v in pair["yardsticks_ms"].items()}
        pairs.append(pair)
    for name in ("on", "off"):
        print(f"  SAC {name}: chunks {[round(w, 2) for w in walls[name]]} s", flush=True)
    res = _sac_share(statistics.mean(walls["on"]), statistics.mean(walls["off"]), n_updates)
    res["pairs"] = pairs
    if yardsticks is not None:
        res["median_over"] = {k: statistics.median(p["over"][k] for p in pairs)
                              for k in pairs[0]["over"]}
        for k, v in res["median_over"].items():
            print(f"  in-chunk / {k}: median {v:.2f} over {len(pairs)} pairs", flush=True)
    # The first chunk of a run evaluates: its program's trace and compile are the run's.
    first_ev = evaluates(cfg, 0)
    res.update(lower_s=programs[first_ev][1], compile_s=programs[first_ev][2],
               first_chunk_s=firsts[first_ev],
               other_program={"evaluates": not first_ev, "lower_s": programs[not first_ev][1],
                              "compile_s": programs[not first_ev][2]}
               if (not first_ev) in programs else None,
               eval_every_epochs=cfg.eval_every_epochs,
               sac_hidden=list(cfg.sac.hidden), sac_batch_size=cfg.sac.batch_size,
               replay_size=cfg.sac.replay_size, full_buffer=full_buffer,
               sac_schedule=cfg.sac_schedule,
               epochs_timed=[first_epoch, first_epoch + len(plans) - 1],
               plans=[{"epoch": e, "evaluates": evaluates(cfg, e),
                       **{k: v.item() for k, v in vars(pl).items()}} for e, pl in plans])
    print(f"  SAC in the chunk: {res['sac_ms_per_update']:.2f} ms per update; chunk / its SAC "
          f"{res['chunk_over_sac']:.2f}", flush=True)
    return res


# ----------------------------------------------------------------------------- the parts

def part_functions(cfg, env, frozen, lstm_batches: int = 0):
    """The chunk's parts as seed-vmapped jitted functions (argument layouts in the comments);
    "lstm": `lstm_batches` online LSTM batches and, if any, the goal-latent refresh."""
    enc = goal_encoder(cfg)
    e, t, n_ep = cfg.n_envs, cfg.horizon, cfg.episodes_per_epoch
    n_updates = cfg.epoch_env_steps * cfg.sac.updates_per_step

    def sim_one(env_state, key):  # env_state [E]; -> poses [ep, T+1, E, ...] for render
        def episode(es, k):
            k_reset, k_act = jax.random.split(k)
            es = jax.vmap(env.reset_episode)(es, jax.random.split(k_reset, e))

            def step(es, k):
                a = jax.random.uniform(k, (e, env.action_size), minval=-1.0, maxval=1.0)
                es = jax.vmap(env.step)(es, a)
                return es, (es.data.geom_xpos, es.data.geom_xmat)

            pose0 = (es.data.geom_xpos, es.data.geom_xmat)
            es, poses = jax.lax.scan(step, es, jax.random.split(k_act, t))
            poses = jax.tree.map(lambda p0, p: jnp.concatenate([p0[None], p], 0), pose0, poses)
            return es, poses

        return jax.lax.scan(episode, env_state, jax.random.split(key, n_ep))

    def render_one(template, poses):  # template: one EnvState; poses [ep, T+1, E, ...]
        def frame(_, pose):
            xpos, xmat = pose
            states = jax.vmap(lambda p, m: template.replace(
                data=template.data.replace(geom_xpos=p, geom_xmat=m)))(xpos, xmat)
            return None, jax.vmap(env.render)(states)

        flat = jax.tree.map(lambda x: x.reshape((n_ep * (t + 1),) + x.shape[2:]), poses)
        _, rgb = jax.lax.scan(frame, None, flat)  # [ep*(T+1), E, H, W, 3]
        return rgb.reshape((n_ep, t + 1) + rgb.shape[1:]).swapaxes(1, 2)  # [ep, E, T+1, ...]

    def segment_one(fz, rgb):  # rgb [ep, E, T+1, H, W, 3]
        return enc.goal_images(fz, rgb)

    def encoders_one(fz, scene_params, lstm_params, rgb, goal_imgs, key):
        def episode(_, xs):
            rgb_ep, g_ep, k = xs  # [E, T+1, ...]

            def step(_, frame):  # the policy's observation, one step of all envs
                return None, models.encode_mean(scene_params, cfg.scene, frame)

            _, z_steps = jax.lax.scan(step, None, rgb_ep[:, :t].swapaxes(0, 1))
            goals = enc.prior_goals(k, lstm_params, e)
            obs = models.encode_mean(scene_params, cfg.scene, rgb_ep)
            achieved = jax.vmap(lambda f: enc.sequence(lstm_params, f))(
                enc.frame_latents(fz, scene_params, g_ep))
            return None, (z_steps.sum(), goals.sum(), obs.sum(), achieved.sum())

        return jax.lax.scan(episode, None, (rgb, goal_imgs, jax.random.split(key, n_ep)))[1]

    def log_p_one(scene_params, rgb, key):  # rgb [ep, E, T+1, ...]
        def episode(_, xs):
            return None, skewfit.frame_log_p(cfg, scene_params, *xs)

        return jax.lax.scan(episode, None, (rgb, jax.random.split(key, n_ep)))[1]

    def policy_one(policy_params, z_steps, goals, key):  # z_steps [ep, T, E, d]; goals [ep, E, g]
        def episode(_, xs):
            z_ep, g, k = xs

            def step(_, zk):
                z, kk = zk
                return None, sac.select_action(policy_params, z, g, kk, cfg=cfg.sac)

            return None, jax.lax.scan(step, None, (z_ep, jax.random.split(k, t)))[1]

        return jax.lax.scan(episode, None, (z_steps, goals, jax.random.split(key, n_ep)))[1]

    def prior_of(state, key):  # the chunk's prior-goal bank (her.goal_prior)
        return her.goal_prior(cfg, enc, env, state.buffer, key, lstm_params_of(state))

    def sac_one(state, key):
        k_bank, k = jax.random.split(key)
        s, m = loop.sac_updates(cfg, enc, state, k, n_updates, prior_of(state, k_bank))
        return s.sac, m

    collector = Collector(cfg, env, enc, evaluate=True)

    def collect_one(fz, state, key, act_random):
        k_bank, key = jax.random.split(key)
        # SAC off: the collection phase alone (with sac_schedule "step" the updates would run
        # inside it; they are timed by "sac").
        plan = ChunkPlan(learn=jnp.bool_(False), act_random=act_random,
                         vae_batches=jnp.int32(0), lstm_batches=jnp.int32(0),
                         refresh_goals=jnp.bool_(False))
        inputs = ChunkInputs(frozen=fz, plan=plan, bank=prior_of(state, k_bank),
                             eval_policy=state.sac.policy_params)

        def episode(s, k):
            ep = collect_episode(collector, inputs, s, k, 0)
            # Reductions of every trajectory field keep all of it alive (no dead code).
            sums = jax.tree.map(lambda x: jnp.sum(x.astype(jnp.float32)), (ep.traj, ep.log_p))
            return s.replace(env_state=ep.env_state), (ep.metrics, ep.test, sums)

        s, out = jax.lax.scan(episode, state, jax.random.split(key, n_ep))
        return s.env_state, out

    def lstm_one(fz, state, key):
        if lstm_batches == 0 or state.lstm is None:
            return state.buffer.goal_latents.sum()
        s, _ = online.train_lstm(cfg, enc, fz, state, key, lstm_batches)
        return online.refresh_goals(enc, s).buffer.goal_latents.sum()

    v = jax.vmap
    return {
        "sim": jax.jit(v(sim_one)),
        "render": jax.jit(v(render_one, in_axes=(None, 0))),
        "segment": jax.jit(v(segment_one, in_axes=(None, 0))),
        "encoders": jax.jit(v(encoders_one, in_axes=(None, 0, 0, 0, 0, 0))),
        "log_p": jax.jit(v(log_p_one)),
        "policy": jax.jit(v(policy_one)),
        "sac": jax.jit(v(sac_one)),
        "collect": jax.jit(v(collect_one, in_axes=(None, 0, 0, None))),
        "lstm": jax.jit(v(lstm_one, in_axes=(None, 0, 0))),
    }


# ----------------------------------------------------------------------------- one seed count

def bench_seeds(a, seeds: int, env) -> dict:
    cfg = make_cfg(a, seeds)
    enc = goal_encoder(cfg)
    key = jax.random.PRNGKey(a.seed)
    k_fz, k_init, k_parts = jax.random.split(key, 3)
    frozen, scene_vae, lstm = fresh_frozen_and_pretrained(cfg, k_fz)
    state = jax.jit(jax.vmap(lambda k: init_state(k, cfg, env, scene_vae, lstm)))(
        jax.random.split(k_init, seeds))
    _block(state)
    plan = ChunkPlan(learn=jnp.bool_(True), act_random=jnp.bool_(False),
                     vae_batches=jnp.int32(a.vae_batches),
                     lstm_batches=jnp.int32(a.lstm_batches),
                     refresh_goals=jnp.bool_(a.lstm_batches > 0 or a.vae_batches > 0))
    steps_per_chunk = seeds * cfg.epoch_env_steps
    n_updates = cfg.epoch_env_steps * cfg.sac.updates_per_step
    print(f"\n== {cfg.task}, {seeds} seed(s): {cfg.n_envs} envs x {cfg.episodes_per_epoch} "
          f"episode(s) x {cfg.horizon} steps = {cfg.epoch_env_steps} env steps per seed per chunk, "
          f"{n_updates} SAC updates per seed at batch {cfg.sac.batch_size}", flush=True)

    # 1. the chunk, exactly as train.run builds it
    seed_batch = sharding.resolve_seed_batch(a.seed_batch, seeds)
    chunk = loop.compile_chunk(cfg, env, 1, seed_batch)
    compiled, lower_s, compile_s = _compile(chunk, state, frozen, plan)
    print(f"  chunk     compile {compile_s:6.1f} s (trace+lower {lower_s:5.1f} s)", flush=True)
    times, cpus = [], []
    for i in range(a.chunks):
        (state, metrics), w, c = _call(compiled, state, frozen, plan)
        times.append(w)
        cpus.append(c)
        print(f"  chunk {i + 1}/{a.chunks}: wall {w:8.2f} s  cpu {c:8.2f} s"
              f"{'  (warm-up, not in steady state)' if i == 0 else ''}", flush=True)
    finite = bool(all(jnp.all(jnp.isfinite(x)) for x in jax.tree.leaves(metrics)))
    steady = times[1:]
    # The same compiled chunk without SAC: what the chunk spends on its own updates.
    no_learn = plan.replace(learn=jnp.bool_(False))
    off = []
    for i in range(a.chunks):
        (state, _), w, _ = _call(compiled, state, frozen, no_learn)
        off.append(w)
    sac_share = _sac_share(statistics.median(steady), statistics.median(off[1:]), n_updates)
    chunk_res = {"seed_batch": seed_batch, "lower_s": lower_s, "compile_s": compile_s,
                 "first_chunk_s": times[0],
                 "steady_chunk_times_s": steady, "steady_chunk_median_s": statistics.median(steady),
                 "steady_chunk_min_s": min(steady), "steady_chunk_cpu_times_s": cpus[1:],
                 "steady_chunk_cpu_median_s": statistics.median(cpus[1:]),
                 "metrics_finite": finite, "without_sac": sac_share,
                 "env_steps_per_s": steps_per_chunk / statistics.median(steady),
                 "env_steps_per_s_per_seed": cfg.epoch_env_steps / statistics.median(steady)}
    print(f"  chunk without SAC {sac_share['chunk_without_sac_s']:.2f} s: SAC in the chunk "
          f"{sac_share['sac_ms_per_update']:.2f} ms per update, chunk / its SAC "
          f"{sac_share['chunk_over_sac']:.2f}", flush=True)
    print(f"  chunk steady state: median {chunk_res['steady_chunk_median_s']:.2f} s -> "
          f"{chunk_res['env_steps_per_s']:.1f} env steps/s ({seeds} seeds), "
          f"{chunk_res['env_steps_per_s_per_seed']:.1f} per seed", flush=True)

    # 2. the parts, at one chunk's sizes, on the state the chunks left
    fns = part_functions(cfg, env, frozen, a.lstm_batches)
    keys = jax.random.split(k_parts, 4 * seeds).reshape(4, seeds, -1)
    parts = {}
    parts["sim"], (_, poses) = _time_part("sim", fns["sim"], (state.env_state, keys[0]), a.reps)
    template = jax.tree.map(lambda x: x[0, 0], state.env_state)
    parts["render"], rgb = _time_part("render", fns["render"], (template, poses), a.reps)
    parts["segment"], goal_imgs = _time_part("segment", fns["segment"], (frozen, rgb), a.reps)
    lstm_params = lstm_params_of(state)
    parts["encoders"], _ = _time_part(
        "encoders", fns["encoders"],
        (frozen, state.scene_vae.params, lstm_params, rgb, goal_imgs, keys[1]), a.reps)
    parts["log_p"], _ = _time_part("log_p", fns["log_p"],
                                   (state.scene_vae.params, rgb, keys[2]), a.reps)
    ep, t = cfg.episodes_per_epoch, cfg.horizon
    z_steps = jax.random.normal(keys[2, 0], (seeds, ep, t, cfg.n_envs, cfg.scene.latent_dim))
    goals = jax.random.normal(keys[2, 1], (seeds, ep, cfg.n_envs, enc.goal_dim))
    parts["policy"], _ = _time_part("policy", fns["policy"],
                                    (state.sac.policy_params, z_steps, goals, keys[3]), a.reps)
    parts["sac"], _ = _time_part("sac", fns["sac"], (state, keys[0]), a.reps)
    parts["lstm"], _ = _time_part("lstm", fns["lstm"], (frozen, state, keys[3]), a.reps)
    collect = None
    if a.collect:
        collect, _ = _time_part("collect", fns["collect"],
                                (frozen, state, keys[1], jnp.bool_(False)), a.reps)
    total = sum(parts[p]["median_s"] for p in PARTS)
    cpu_total = sum(parts[p]["cpu_median_s"] for p in PARTS)
    for p in PARTS:
        parts[p]["share_of_sum"] = parts[p]["median_s"] / total
        parts[p]["cpu_share_of_sum"] = parts[p]["cpu_median_s"] / cpu_total
    res = {
        "seeds": seeds,
        "sizes": {"n_envs": cfg.n_envs, "horizon": cfg.horizon,
                  "episodes_per_chunk": cfg.episodes_per_epoch,
                  "env_steps_per_chunk_per_seed": cfg.epoch_env_steps,
                  "env_steps_per_chunk": steps_per_chunk,
                  "rendered_frames_per_chunk": seeds * cfg.n_envs * ep * (t + 1),
                  "sac_updates_per_chunk_per_seed": n_updates,
                  "sac_batch_size": cfg.sac.batch_size, "sac_hidden": list(cfg.sac.hidden),
                  "replay_capacity_trajectories": cfg.sac.replay_capacity(cfg.horizon),
                  "scene_latent": cfg.scene.latent_dim, "object_latent": cfg.object_vae.latent_dim,
                  "lstm_hidden": cfg.lstm.hidden, "lstm_layers": cfg.lstm.layers,
                  "unet_features": cfg.segmentation.unet_features},
        "plan": {"learn": True, "act_random": False, "vae_batches": a.vae_batches,
                 "lstm_batches": a.lstm_batches},
        "chunk": chunk_res,
        "parts": parts,
        "parts_sum_s": total,
        "parts_cpu_sum_s": cpu_total,
        "chunk_over_parts_sum": chunk_res["steady_chunk_median_s"] / total,
        "chunk_over_parts_sum_cpu": chunk_res["steady_chunk_cpu_median_s"] / cpu_total,
        "collect_phase": collect,
    }
    print(f"  sum of parts {total:.2f} s (cpu {cpu_total:.2f} s); chunk "
          f"{chunk_res['steady_chunk_median_s']:.2f} s (cpu "
          f"{chunk_res['steady_chunk_cpu_median_s']:.2f} s); ratio chunk / parts: wall "
          f"{res['chunk_over_parts_sum']:.2f}, cpu {res['chunk_over_parts_sum_cpu']:.2f}"
          + (f"; collect phase {collect['median_s']:.2f} s" if collect else ""), flush=True)
    return res


def table(results: list[dict]) -> str:
    """Per seed count: wall s (median), its share of the parts' sum, CPU s (median, all
    threads), its share, compile s."""
    width = 46
    lines = ["part        " + "".join(f"{str(r['seeds']) + ' seed(s)':>{width}s}" for r in results),
             "            " + "".join(f"{'wall s':>10s}{'share':>8s}{'cpu s':>10s}{'share':>8s}"
                                     f"{'compile s':>10s}" for _ in results)]
    for p in PARTS:
        row = f"{p:12s}"
        for r in results:
            q = r["parts"][p]
            row += (f"{q['median_s']:10.3f}{100 * q['share_of_sum']:7.1f}%"
                    f"{q['cpu_median_s']:10.3f}{100 * q['cpu_share_of_sum']:7.1f}%"
                    f"{q['compile_s']:10.1f}")
        lines.append(row)

    def plain(name, get):
        row = f"{name:12s}"
        for r in results:
            wall, cpu, comp = get(r)
            row += (f"{wall:10.3f}{'':8s}{cpu:10.3f}{'':8s}"
                    + (f"{comp:10.1f}" if comp is not None else f"{'':10s}"))
        lines.append(row)

    plain("sum of parts", lambda r: (r["parts_sum_s"], r["parts_cpu_sum_s"], None))
    if all(r["collect_phase"] is not None for r in results):
        plain("collect", lambda r: (r["collect_phase"]["median_s"],
                                    r["collect_phase"]["cpu_median_s"],
                                    r["collect_phase"]["compile_s"]))
    plain("whole chunk", lambda r: (r["chunk"]["steady_chunk_median_s"],
                                    r["chunk"]["steady_chunk_cpu_median_s"],
                                    r["chunk"]["compile_s"]))
    row = f"{'env steps/s':12s}"
    for r in results:
        row += f"{r['chunk']['env_steps_per_s']:10.1f}{'':{width - 10}s}"
    lines.append(row)
    return "\n".join(lines)


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m bench chunk", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--task", default="puck_push", choices=envs_mjx.TASK_NAMES,
                   help="the task (default puck_push)")
    p.add_argument("--seeds", type=int, nargs="+", default=[1, 6],
                   help="seed counts, one chunk program each (default 1 6)")
    p.add_argument("--preset", default="paper", choices=PRESETS,
                   help="the networks' preset (default paper)")
    p.add_argument("--epoch-env-steps", type=int, default=None,
                   help="env steps per seed per chunk, a multiple of n_envs x horizon "
                   "(default: the preset's, 500 for paper)")
    p.add_argument("--n-envs", type=int, default=None,
                   help="envs per seed (default: the preset's, 10 for the push tasks)")
    p.add_argument("--chunks", type=int, default=3, help="chunks per seed count; the first is a "
                   "warm-up, the rest are timed")
    p.add_argument("--reps", type=int, default=2, help="timed calls per part after the warm-up")
    p.add_argument("--replay-size", type=int, default=None,
                   help="replay capacity in transitions (default: the preset's)")
    p.add_argument("--vae-batches", type=int, default=0,
                   help="scheduled scene-VAE batches per chunk (0: steady state without)")
    p.add_argument("--lstm-batches", type=int, default=0,
                   help="online LSTM batches per chunk (0: steady state without)")
    p.add_argument("--no-collect", dest="collect", action="store_false",
                   help="skip timing the collection phase as one function (saves its compile)")
    p.add_argument("--seed-batch", default="auto",
                   help="seeds vmapped together in the chunk, the rest mapped (as train.py; "
                        "auto: 1 on CPU, all on GPU)")
    p.add_argument("--seed", type=int, default=0, help="PRNG seed (default 0)")
    p.add_argument("--out", default=result_path("chunk"), help="result file")
    a = p.parse_args(argv)
    machine = machine_info()
    env = envs_mjx.make(a.task)
    preset = make_config(a.task, "roll", a.preset)
    a.n_envs = preset.n_envs if a.n_envs is None else a.n_envs
    a.epoch_env_steps = preset.epoch_env_steps if a.epoch_env_steps is None else a.epoch_env_steps
    if a.chunks < 2:
        p.error("--chunks must be >= 2 (the first chunk is a warm-up)")
    try:
        make_cfg(a, 1)
    except ValueError as e:
        p.error(str(e))
    t0 = time.perf_counter()
    res = {
        "task": a.task, "preset": a.preset, "args": vars(a),
        "note": ("whole chunk = loop.compile_chunk (the training code path), compile timed "
                 "apart (AOT lower + compile), steady state = median of chunks 2.."
                 "--chunks; parts = each its own jitted function at one chunk's sizes, median of at "
                 "least --reps calls after a warm-up (fast parts repeat up to 1 s or 20 calls), "
                 "shares of the parts' sum; wall and process CPU seconds. Segmentation and "
                 "encoder weights are freshly initialised (random): throughput does not depend on "
                 "training them. Plan: the policy acts, SAC learns, scheduled VAE/LSTM training "
                 "as in args (0 = off). The machine may be shared with other jobs (see load "
                 "averages)."),
        "runs": [],
    }
    print(res["note"], flush=True)
    for s in a.seeds:
        res["runs"].append(bench_seeds(a, s, env))
    res["wall_s"] = time.perf_counter() - t0
    print()
    print(table(res["runs"]))
    print(f"\nwall {res['wall_s']:.0f} s; load average {list(os.getloadavg())}")
    write_result("chunk", res, machine, argv, a.out)


if __name__ == "__main__":
    main()
