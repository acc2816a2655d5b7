"""The training driver: segmentation -> pre-training -> chunks of the compiled loop.

`run(cfg, out, ...)` is what `train.py` calls. Every `eval_every_epochs`-th chunk also
evaluates the policy it starts from (test envs in the collection batch,
`collect.collect_episode`; the other chunks run a program without them); between chunks Python
logs every chunk's training metrics and speed to TensorBoard (DIR/tb, `events`), appends each
evaluation to metrics.csv and TensorBoard, checkpoints (orbax, the whole train state including
the replay buffer), plots the learning curve and drives the progress bar; at the end it writes
timings.json (wall and CPU seconds per phase; the first chunk's include its compile). Seeds are
the state's leading axis, vmapped or mapped (`roll_jax.training.sharding.over_seeds`); with
several devices that axis is sharded over them, on one host or several (process 0 writes the
files). A finished run gets `COMPLETE_MARKER` (complete.json), written atomically last. While it
runs, DIR/train.lock names its process: a second run into DIR is refused.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import functools
import json
import os
import time

import jax
import numpy as np

from configs.train import TrainConfig
from roll_jax.common.checkpoint import restore_train_state, save_train_state, train_state_manager
from roll_jax.encoders import pretrain
from roll_jax.encoders.goal_encoding import Frozen, goal_encoder
from roll_jax.training import events, loop, plots, run_dir
from roll_jax.training import sharding as shd
from roll_jax.training.run_dir import COMPLETE_MARKER, check_resume
from roll_jax.training.state import TrainState, eval_only_plan, init_state, plan_chunk

LOSS_KEYS = ("q_loss", "policy_loss", "alpha_loss", "vae_loss", "lstm_loss")
class TrainingDiverged(RuntimeError):
    pass


def check_finite(train: dict, env_steps: int, epoch: int, ckpt: str) -> None:
    """Stop on a NaN/inf loss, or on a chunk where any SAC update had a non-finite gradient
    (`sac_update`'s "finite" flag; the chunk reports its mean, < 1 when one was not),
    naming the quantity, the seed and the env step. Called before the chunk's state is
    checkpointed, so the last good checkpoint is kept."""
    for k in LOSS_KEYS:
        if k in train and not np.all(np.isfinite(train[k])):
            bad = int(np.argmax(~np.isfinite(train[k])))
            raise TrainingDiverged(
                f"{k} is {train[k][bad]} for seed {bad} at env step {env_steps} (epoch "
                f"{epoch}); the last good checkpoint in {ckpt} is kept")
    if "finite" in train:
        flag = np.asarray(train["finite"], np.float64)
        if not np.all(flag == 1.0):  # (1 in a chunk without updates: her.zero_sac_metrics)
            bad = int(np.argmax(flag != 1.0))
            raise TrainingDiverged(
                f"a SAC gradient was NaN/inf for seed {bad} at env step {env_steps} (epoch "
                f"{epoch}; {1.0 - flag[bad]:.0%} of its updates); the last good checkpoint in "
                f"{ckpt} is kept")


class PhaseTimes:
    """Wall and process-CPU seconds (all threads) per phase of a run, for timings.json;
    `with times("name"):` adds one entry to the phase's list."""

    def __init__(self):
        self.wall: dict[str, list[float]] = {}
        self.cpu: dict[str, list[float]] = {}

    @contextlib.contextmanager
    def __call__(self, name: str):
        w, c = time.perf_counter(), time.process_time()
        try:
            yield
        finally:
            self.wall.setdefault(name, []).append(round(time.perf_counter() - w, 2))
            self.cpu.setdefault(name, []).append(round(time.process_time() - c, 2))

    def as_dict(self) -> dict:
        return {"wall_s": self.wall, "cpu_s": self.cpu}


def check_given(**paths) -> None:
    """FileNotFoundError naming the first given checkpoint directory without a meta.json
    (keywords: the option names, e.g. seg_ckpt=..., enc_ckpt=...; None = not given)."""
    for name, path in paths.items():
        if path is not None and not os.path.exists(os.path.join(path, "meta.json")):
            raise FileNotFoundError(f"{name}={path!r} is not a checkpoint directory (no "
                                    f"meta.json in it)")


def setup(cfg: TrainConfig, env, key, out: str, seg_ckpt=None, enc_ckpt=None, progress=True,
          times: PhaseTimes | None = None, pretrain_cache: str | None = None):
    """Segmentation and encoders (fitted, or loaded from the given/previous checkpoints;
    `pretrain_cache`: datasets and models shared with other runs, `pretrain.pretrain`);
    their times go to `times` (phases "segmentation" and "pretrain")."""
    times = PhaseTimes() if times is None else times
    enc = goal_encoder(cfg)
    k_seg, k_pre = jax.random.split(key)
    # Named encoders must exist: pretraining fresh ones in their place would hide a wrong path
    # behind minutes of work. (A segmentation directory is fitted into when empty: the grid
    # shares one per task that way; the CLIs check a user's --seg-ckpt: `check_given`.)
    check_given(enc_ckpt=enc_ckpt)
    seg = None
    with times("segmentation"):
        if enc.segment:
            seg = pretrain.fit_or_load_segmentation(
                cfg, env, seg_ckpt or os.path.join(out, "segmentation"), k_seg)
    enc_path = enc_ckpt or os.path.join(out, "encoders")
    with times("pretrain"):
        if not enc.from_pixels:  # the oracle: the untrained scene-VAE only fills the slot
            pre = pretrain.initial(cfg, k_pre)
        elif os.path.exists(os.path.join(enc_path, "meta.json")):
            pre = pretrain.load(enc_path, cfg)
        else:
            pre, _ = pretrain.pretrain(cfg, env, seg, k_pre, progress=progress,
                                       cache=pretrain_cache)
            pretrain.save(enc_path, cfg, pre)
    frozen = Frozen(seg=seg, object_vae=None if pre.object_vae is None else pre.object_vae.params)
    return frozen, pre


def compile_in_background(fn, *args):
    """A jitted `fn` lowered and compiled for the shapes and placements of `args` in another
    thread -> a callable that waits for that compile on its first call. XLA compiles a
    program on one core, so on a 2-core CPU a second program compiles while the first one
    compiles or runs."""
    abstract = jax.tree.map(
        lambda x: jax.ShapeDtypeStruct(x.shape, x.dtype, sharding=x.sharding), args)
    pool = concurrent.futures.ThreadPoolExecutor(1)
    future = pool.submit(lambda: fn.lower(*abstract).compile())
    pool.shutdown(wait=False)
    return lambda *a: future.result()(*a)


def init_seeds(cfg: TrainConfig, env, key, pre: pretrain.Pretrained,
               sharding: shd.SeedSharding | None = None) -> TrainState:
    """[seeds]-batched train state; every seed starts from the same pre-trained encoders."""
    return init_states(cfg, env, jax.random.split(key, cfg.seeds), pre, sharding)


def init_states(cfg: TrainConfig, env, keys, pre: pretrain.Pretrained,
                sharding: shd.SeedSharding | None = None) -> TrainState:
    """One seed per key [S, 2]. With a `sharding` each device builds its own seeds' state
    (nothing gathered on one device)."""
    if sharding is None:
        # Committed to the device like every chunk's output (the frozen params are), so the
        # first chunk call compiles the same program as the later ones.
        return jax.device_put(_init_fn(cfg, env, None)(keys, pre.scene_vae, pre.lstm),
                              jax.devices()[0])
    encoders = sharding.replicate((pre.scene_vae, pre.lstm))
    return _init_fn(cfg, env, sharding.seeds)(sharding.shard(keys), *encoders)


@functools.lru_cache(maxsize=4)
def _init_fn(cfg: TrainConfig, env, out_shardings):
    """jit of the seeds' initial states, built once per config (like `loop.compile_chunk`);
    the encoders are arguments, not constants baked into the program."""
    init = jax.vmap(lambda k, vae, lstm: init_state(k, cfg, env, vae, lstm),
                    in_axes=(0, None, None))
    return jax.jit(init) if out_shardings is None else jax.jit(init, out_shardings=out_shardings)


def run(cfg: TrainConfig, out: str, resume: bool = False, seg_ckpt: str | None = None,
        enc_ckpt: str | None = None, seed: int = 0, progress: bool = True,
        stop_after_epochs: int | None = None, devices="all", seed_batch="auto",
        pretrain_cache: str | None = None) -> list[dict]:
    """Train `cfg.seeds` seeds; returns the metrics rows. `stop_after_epochs` ends early (as an
    interruption would; tests use it for resume). `devices` ('all' or N) shards the seed axis
    over that many devices (seeds must divide evenly), those of every process after
    `jax.distributed.initialize`; one device is the unsharded path. `seed_batch` ('auto' or N):
    seeds vmapped together per device, the rest mapped (`sharding.resolve_seed_batch`).
    `pretrain_cache`: a directory of pre-training datasets and models shared between runs (the
    reproduction grid's).

    Refused before anything is written: a directory another live process trains into
    (`run_dir.RunLocked`), an event directory that cannot be written
    (`events.EventDirNotWritable`); with `resume`, a run whose checkpoints are all damaged
    (`DamagedCheckpoint`) after setup."""
    if resume:
        check_resume(out, cfg, seed)
    sharding = shd.make(devices, cfg.seeds)  # the divisibility error comes before any compile
    lock = run_dir.lock_run(out) if shd.is_main_process() else None
    try:
        if lock is not None:
            events.check_writable(out)
        return _run(cfg, out, resume, seg_ckpt, enc_ckpt, seed, progress, stop_after_epochs,
                    sharding, seed_batch, pretrain_cache)
    finally:
        if lock is not None:
            lock.release()


def _restore(cfg: TrainConfig, out: str, mgr, state):
    """(epoch, state, manager) from the newest readable checkpoint. A damaged step is named on
    stderr and the one before it tried; once one restores, the damaged step directories are
    moved to DIR/ckpt_damaged/ (kept, and out of the way of the steps the run saves again).
    When none restores they stay where they are (DamagedCheckpoint)."""
    # The live state's placement (one device, or the seed sharding): a checkpoint written on
    # another device count restores onto this one.
    abstract = jax.tree.map(
        lambda x: jax.ShapeDtypeStruct(x.shape, x.dtype, sharding=x.sharding), state)
    ckpt = os.path.join(out, "ckpt")
    damaged = []

    def on_damaged(step: int, reason: str) -> None:
        damaged.append(step)
        run_dir.warn(f"checkpoint {ckpt}/{step} (epoch {step}) is damaged: {reason}")

    epoch, state = restore_train_state(mgr, abstract, on_damaged)
    if damaged:
        moved = []
        if shd.is_main_process():
            for step in damaged:
                dst = os.path.join(out, "ckpt_damaged", str(step))
                n = 1
                while os.path.exists(dst):
                    dst, n = os.path.join(out, "ckpt_damaged", f"{step}.{n}"), n + 1
                os.makedirs(os.path.dirname(dst), exist_ok=True)
                os.replace(os.path.join(ckpt, str(step)), dst)
                moved.append(dst)
            run_dir.warn(f"resuming from {ckpt}/{epoch} ({epoch * cfg.epoch_env_steps} env "
                         f"steps); the damaged checkpoint(s) moved to {', '.join(moved)}")
        if jax.process_count() > 1:  # every process's manager sees the steps moved
            from jax.experimental import multihost_utils

            multihost_utils.sync_global_devices("roll_jax: damaged checkpoints moved")
        mgr.close()  # a manager that knows the steps left
        mgr = train_state_manager(out, cfg.keep_checkpoints)
    return epoch, state, mgr


def _run(cfg: TrainConfig, out: str, resume: bool, seg_ckpt, enc_ckpt, seed: int,
         progress: bool, stop_after_epochs, sharding, seed_batch, pretrain_cache) -> list[dict]:
    from tqdm import tqdm

    import envs_mjx

    n_devices = 1 if sharding is None else sharding.n_devices
    per_device = shd.resolve_seed_batch(seed_batch, cfg.seeds, n_devices)
    main = shd.is_main_process()
    if main:
        os.makedirs(os.path.join(out, "plots"), exist_ok=True)
        os.makedirs(os.path.join(out, "videos"), exist_ok=True)
        run_dir.write_config(out, cfg)
        run_dir.write_inputs(out, seg_ckpt, enc_ckpt, seed)

    times = PhaseTimes()  # this process's phases -> timings.json
    t_run, c_run = time.perf_counter(), time.process_time()
    env = envs_mjx.make(cfg.task)
    key = jax.random.PRNGKey(seed)
    k_setup, k_init, _ = jax.random.split(key, 3)  # (the third key: evaluation, now in-chunk)
    frozen, pre = setup(cfg, env, k_setup, out, seg_ckpt, enc_ckpt, progress, times,
                        pretrain_cache)
    with times("init"):
        state = jax.block_until_ready(init_seeds(cfg, env, k_init, pre, sharding))
    # Committed like the state: fresh (uncommitted) and restored (committed) parameters would
    # otherwise compile two programs for one config, and miss each other's cache entries.
    frozen = jax.device_put(frozen, jax.devices()[0]) if sharding is None else (
        sharding.replicate(frozen))
    mgr = train_state_manager(out, cfg.keep_checkpoints)
    csv_path = os.path.join(out, "metrics.csv")
    start_epoch = 0
    if resume and mgr.latest_step() is not None:
        start_epoch, state, mgr = _restore(cfg, out, mgr, state)
        if sharding is not None:
            state = sharding.shard(state)
    # metrics.csv and the event files as of the checkpoint (a new run: empty): what the chunks
    # after it logged is dropped, they run again. Rows before it; a finished run's final
    # evaluation too.
    keep = start_epoch * cfg.epoch_env_steps if resume else None
    final = start_epoch == cfg.n_epochs
    if main:
        marker = os.path.join(out, COMPLETE_MARKER)
        if os.path.exists(marker):  # being redone or continued: not complete until the end
            os.remove(marker)
        rows = run_dir.restart_rows(csv_path, keep, final)
        log = events.EventLog(out, keep, final)
        if keep is None:
            log.config(run_dir.config_json(cfg))
    else:
        rows, log = run_dir.read_rows(csv_path, -1 if keep is None else keep, final), None
    end_epoch = cfg.n_epochs if stop_after_epochs is None else min(cfg.n_epochs, stop_after_epochs)
    # Two programs: chunks whose evaluation is logged run the test envs beside the training
    # envs, the others leave them out. The second compiles in the background from the start.
    chunks = {ev: loop.compile_chunk(cfg, env, n_devices, per_device, evaluate=ev)
              for ev in (True, False)}
    if cfg.eval_every_epochs > 1 and any(
            e % cfg.eval_every_epochs for e in range(start_epoch, end_epoch)):
        chunks[False] = compile_in_background(chunks[False], state, frozen,
                                              plan_chunk(cfg, start_epoch))
    if sharding is not None:
        chunks = {ev: sharding.wrap_chunk(c) for ev, c in chunks.items()}

    def log_evaluation(env_steps: int, ev: dict) -> None:
        """One metrics.csv row per seed: the evaluation of the policy after `env_steps` and
        the training metrics of the chunk that ended there (zeros at 0)."""
        new = []
        for s in range(cfg.seeds):
            row = {"env_steps": env_steps, "seed": s,
                   "final_distance": float(ev["final_distance"][s]),
                   "final_distance_median": float(ev["final_distance_median"][s]),
                   "start_distance": float(ev["start_distance"][s])}
            row.update({k: float(v[s]) for k, v in ev["train"].items()})
            new.append(row)
        rows.extend(new)
        if main:
            run_dir.write_gif(os.path.join(out, "videos", f"eval_{env_steps:08d}.gif"),
                              ev["video"][0], ev["goal_image"][0])
            run_dir.append_rows(csv_path, new)
            log.evaluation(env_steps, ev)
            log.flush()
            plots.learning_curve(rows, os.path.join(out, "plots", "learning_curve.png"),
                           f"{cfg.task} ({cfg.algo}, {cfg.seeds} seeds)")

    bar = tqdm(range(start_epoch, end_epoch), desc=f"{cfg.task} {cfg.algo}", unit="epoch",
               disable=not (progress and main), initial=start_epoch, total=cfg.n_epochs)
    t_last = time.perf_counter()
    try:
        for epoch in bar:
            plan = plan_chunk(cfg, epoch)
            evaluate = epoch % cfg.eval_every_epochs == 0
            with times("chunks"):  # the first of each program includes tracing and compiling
                state, metrics = chunks[evaluate](state, frozen, plan)
                metrics = shd.to_host(metrics)
            env_steps = (epoch + 1) * cfg.epoch_env_steps
            check_finite(metrics["train"], env_steps, epoch, os.path.join(out, "ckpt"))
            now = time.perf_counter()
            # Chunk end to chunk end: the chunk and the host's work between chunks.
            rate = cfg.epoch_env_steps * cfg.seeds / max(now - t_last, 1e-9)
            if main:
                log.chunk(env_steps, metrics["train"], now - t_last, rate, now - t_run)
            t_last = now
            if evaluate:
                log_evaluation(epoch * cfg.epoch_env_steps, metrics["eval"])
                bar.set_postfix(dist=f"{np.median(metrics['eval']['final_distance']):.3f}",
                                start=f"{np.median(metrics['eval']['start_distance']):.3f}",
                                sps=f"{rate:.0f}")
            elif main:
                log.flush()
            if (epoch + 1) % cfg.checkpoint_every_epochs == 0 or epoch + 1 == cfg.n_epochs:
                save_train_state(mgr, epoch + 1, state)
        _finish(cfg, state, frozen, chunks, mgr, rows, times, end_epoch, log_evaluation)
    finally:
        if log is not None:
            log.close()
    if main:
        with open(os.path.join(out, "timings.json"), "w") as f:
            json.dump({**times.as_dict(), "total_wall_s": round(time.perf_counter() - t_run, 2),
                       "total_cpu_s": round(time.process_time() - c_run, 2)}, f, indent=2)
    if main and end_epoch == cfg.n_epochs:
        run_dir.write_atomic(os.path.join(out, COMPLETE_MARKER), json.dumps(
            {"env_steps": cfg.total_env_steps, "seeds": cfg.seeds, "task": cfg.task,
             "algo": cfg.algo, "devices": n_devices, "seed_batch": per_device},
            indent=2))
    return rows


def _finish(cfg, state, frozen, chunks, mgr, rows, times, end_epoch, log_evaluation):
    """The last checkpoint on disk and, for a run that reached its end, the final policy's
    evaluation (unless a resumed finished run has it already)."""
    mgr.wait_until_finished()  # the state is donated below: the checkpoint must be on disk
    evaluated = any(r["env_steps"] == cfg.total_env_steps for r in rows)  # resumed, finished
    if end_epoch == cfg.n_epochs and not evaluated:
        # The final policy: one more chunk that only collects (and evaluates); its state is
        # dropped, the checkpoint above is the run's end.
        with times("final_eval"):
            _, metrics = chunks[True](state, frozen, eval_only_plan())
            metrics = shd.to_host(metrics)
        log_evaluation(cfg.total_env_steps, metrics["eval"])
    mgr.wait_until_finished()
    mgr.close()
