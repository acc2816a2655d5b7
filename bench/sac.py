"""Where a SAC update's time goes at the cpu preset: the update alone (as bench/roofline.py
times it, and with what it drops put back), HER sampling alone, and `her.sac_steps` (sampling
+ update, as the chunk runs it).

Sizes: the cpu preset's SAC (128-128, batch 256), 6-d latents, 2-d actions, a filled buffer of
1000 episodes x 51 frames of random latents, ROLL's prior-goal bank (`goal_encoding.PRIOR_BANK`).
Each variant runs --steps updates in one jitted `lax.scan`; the best call after a warm-up
(`bench.common.time_best`: at least 3 calls, more until 1 s was timed). "interleaved" runs
`her.sac_steps` as the chunk's "step" schedule does: `updates_per_step x n_envs` updates
under a `lax.cond` inside each step of a scan over env steps, with a 512 x 512 matmul per
step standing in for the env's work (timed with the cond on minus off, as bench/chunk.py
times the chunk). Every variant is compiled twice, with XLA's defaults and
with the chunk's own compiler options (`compiler.chunk_compiler_options`), and timed both ways.
The last row is no scan: `--steps` calls of a jitted `sac.sac_update`, one per update, each on
a batch of its own (best of 3 such loops).

In a scan on one constant batch with its metrics dropped (the roofline's FLOP-rate
yardstick), XLA deletes the metrics' work and hoists what depends on the batch alone out of
the loop: its loop body holds 184 fusions against 251 for the update on a new batch with its
metrics, which is the update the chunk runs (docs/training.md, "What a chunk costs").

    python -m bench sac [--steps 300]
"""
from __future__ import annotations

import argparse
import collections
import re
import time
from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp

from bench.common import machine_info, result_path, time_best, write_result
from configs.train import make_config
from roll_jax.agents import her, replay, sac
from roll_jax.encoders.goal_encoding import PRIOR_BANK, goal_encoder
from roll_jax.training.compiler import chunk_compiler_options


class Variant(NamedTuple):
    """`fn(*args)` runs `updates` updates (or samplings); with `off_args` the time of
    `fn(*off_args)` (the same program, its updates switched off) is subtracted."""
    fn: Callable
    args: tuple
    updates: int
    off_args: Any = None


def _setup():
    """(cfg, SAC state, filled buffer, prior-goal bank, one HER batch, a 512 x 512 matrix for
    the interleaved variant's stand-in env work) at the cpu preset's sizes."""
    cfg = make_config("puck_push", "roll", "cpu")
    scfg = cfg.sac
    b, n, t, d = scfg.batch_size, 1000, cfg.horizon, 6
    ks = jax.random.split(jax.random.PRNGKey(0), 8)
    state = sac.init_sac(ks[7], d, d, 2, scfg)
    buf = replay.init_buffer(n, t, (1, 1, 3), 2, d, d, d)
    buf = buf.replace(obs_latents=jax.random.normal(ks[0], buf.obs_latents.shape),
                      goal_latents=jax.random.normal(ks[1], buf.goal_latents.shape),
                      rollout_goals=jax.random.normal(ks[2], buf.rollout_goals.shape),
                      actions=jax.random.uniform(ks[3], buf.actions.shape, minval=-1, maxval=1),
                      size=jnp.int32(n))
    bank = jax.random.normal(ks[4], (PRIOR_BANK, d))
    fixed = replay.sample_transitions(buf, ks[5], b, bank[:b], scfg.goal_fracs, cfg.reward_norm)
    return cfg, state, buf, bank, fixed, jax.random.normal(ks[6], (512, 512))


def variants(steps: int) -> dict[str, Variant]:
    """name -> Variant; each runs `steps` updates (the interleaved one: rounded up to whole
    env steps)."""
    cfg, state, buf, bank, fixed, work = _setup()
    scfg, enc = cfg.sac, goal_encoder(cfg)
    b = scfg.batch_size
    source = her.FreshGoals(bank=bank)

    def constant_batch(s, k):
        return jax.lax.scan(lambda s, k: (sac.sac_update(s, k, fixed, scfg)[0], None), s,
                            jax.random.split(k, steps))[0]

    def constant_batch_metrics(s, k):
        return jax.lax.scan(lambda s, k: sac.sac_update(s, k, fixed, scfg), s,
                            jax.random.split(k, steps))

    def new_batch_metrics(s, k):
        # Per-step batches the compiler cannot fold: the fixed batch plus 0 x noise.
        noise = jax.random.normal(k, (steps,))
        batches = jax.tree.map(
            lambda x: x[None] + (0.0 * noise).reshape((steps,) + (1,) * x.ndim), fixed)
        return jax.lax.scan(lambda s, xb: sac.sac_update(s, xb[0], xb[1], scfg), s,
                            (jax.random.split(k, steps), batches))

    def her_only(k):
        def body(c, k):
            k1, k2 = jax.random.split(k)
            fresh = her.fresh_goals(enc, buf, source, k1, b)
            x = replay.sample_transitions(buf, k2, b, fresh, scfg.goal_fracs, cfg.reward_norm)
            return c + sum(jnp.sum(v) for v in jax.tree.leaves(x)), None
        return jax.lax.scan(body, 0.0, jax.random.split(k, steps))[0]

    def sac_steps(s, k):
        return her.sac_steps(cfg, enc, s, buf, source, k, steps)

    per_step = cfg.n_envs * scfg.updates_per_step
    env_steps = -(-steps // per_step)  # whole env steps of per_step updates each

    def interleaved(s, k, learn):
        zeros = jax.tree.map(jnp.zeros_like, jax.eval_shape(
            lambda q: her.sac_steps(cfg, enc, q, buf, source, k, per_step)[1], s))

        def step(c, k):
            s, x = c
            x = jnp.tanh(x @ work)
            s, m = jax.lax.cond(
                learn, lambda q: her.sac_steps(cfg, enc, q, buf, source, k, per_step),
                lambda q: (q, zeros), s)
            return (s, x), m
        return jax.lax.scan(step, (s, work), jax.random.split(k, env_steps))

    key = jax.random.PRNGKey(1)
    return {
        "update, constant batch, metrics dropped (roofline standalone)":
            Variant(constant_batch, (state, key), steps),
        "update, constant batch, metrics kept": Variant(constant_batch_metrics, (state, key), steps),
        "update, new batch per update, metrics kept": Variant(new_batch_metrics, (state, key), steps),
        "HER sampling and relabeling alone": Variant(her_only, (key,), steps),
        "her.sac_steps (sampling + update)": Variant(sac_steps, (state, key), steps),
        "interleaved: her.sac_steps inside env steps": Variant(
            interleaved, (state, key, jnp.bool_(True)), env_steps * per_step,
            off_args=(state, key, jnp.bool_(False))),
    }


PER_CALL = "update per call of a jitted sac_update, new batch each"


def per_call_timer(steps: int, compiler_options=None) -> Callable[[], float]:
    """A function -> best ms per update of `steps` updates, each one call of a jitted
    `sac.sac_update` (state donated) on a batch of its own: the update as a standalone
    function, which no loop lets XLA fold into its neighbours (Python's dispatch included)."""
    cfg, state, _, _, fixed, _ = _setup()
    scfg = cfg.sac
    one = jax.jit(lambda s, k, x: sac.sac_update(s, k, x, scfg), donate_argnums=0,
                  compiler_options=compiler_options)
    batches = [jax.tree.map(jnp.copy, fixed) for _ in range(steps)]  # same values, own buffers
    keys = list(jax.random.split(jax.random.PRNGKey(1), steps))

    def loop_once() -> float:
        s = jax.block_until_ready(jax.tree.map(jnp.copy, state))
        t0 = time.perf_counter()
        for k, x in zip(keys, batches):
            s, _ = one(s, k, x)
        jax.block_until_ready(s)
        return time.perf_counter() - t0

    loop_once()  # compile and warm up

    def timer() -> float:
        return 1e3 * min(loop_once() for _ in range(3)) / steps
    return timer


_SKIPPED_OPS = ("parameter", "get-tuple-element", "tuple", "constant", "bitcast")


def loop_body_ops(hlo_text: str) -> dict[str, int]:
    """Op counts of the largest while-loop body in an optimised HLO module's text (the update
    loop of these variants): how much work one update leaves inside its loop."""
    bodies, cur = {}, None
    for line in hlo_text.split("\n"):
        head = re.match(r"^(?:ENTRY )?%?([\w.\-]+) .*\{$", line)
        if head:
            cur = head.group(1)
            bodies[cur] = collections.Counter()
        elif cur is not None and line.startswith("  "):
            op = re.search(r"=\s*\S+\s+([\w\-]+)\(", line)
            if op and op.group(1) not in _SKIPPED_OPS:
                bodies[cur][op.group(1)] += 1
    names = set(re.findall(r"\bwhile\(.*?body=%?([\w.\-]+)", hlo_text))
    if not names:
        return {}
    largest = max(names, key=lambda n: sum(bodies.get(n, {}).values()))
    return dict(bodies[largest].most_common())


def ms_per_update(v: Variant, f) -> float:
    """Best-call ms per update of variant `v` run by `f` (`v.fn` jitted or compiled), minus
    its updates-off time if it has one."""
    seconds = time_best(f, *v.args)[1]
    if v.off_args is not None:
        seconds -= time_best(f, *v.off_args)[1]
    return seconds / v.updates * 1e3


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m bench sac", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--steps", type=int, default=300, help="updates per timed call")
    p.add_argument("--out", default=result_path("sac"), help="result file")
    a = p.parse_args(argv)
    if a.steps <= 0:
        p.error(f"--steps must be positive, got {a.steps}")
    machine = machine_info()
    options = chunk_compiler_options()
    # The chunk's options are left out off a CPU backend or where this jaxlib refuses them.
    settings = [("xla_defaults", None)]
    if options is not None:
        settings.append(("chunk_options", options))
    rows = []
    for name, v in variants(a.steps).items():
        row = {"name": name}
        for label, opts in settings:
            compiled = jax.jit(v.fn, compiler_options=opts).lower(*v.args).compile()
            row[f"ms_per_update_{label}"] = round(ms_per_update(v, compiled), 4)
            if label == "xla_defaults":
                ops = loop_body_ops(compiled.as_text())
                row["loop_body_ops_xla_defaults"] = {k: ops.get(k, 0)
                                                     for k in ("fusion", "dot", "copy")}
        rows.append(row)
    per_call = {"name": PER_CALL}
    for label, opts in settings:
        per_call[f"ms_per_update_{label}"] = round(per_call_timer(a.steps, opts)(), 4)
    rows.append(per_call)
    for row in rows:
        print(f"{row['name']:50s} " + "  ".join(f"{k[14:]} {v:6.3f} ms" for k, v in row.items()
                                                if k.startswith("ms_")),
              row.get("loop_body_ops_xla_defaults", ""), flush=True)
    write_result("sac", {"steps": a.steps, "chunk_compiler_options": options, "rows": rows},
                 machine, argv, a.out)


if __name__ == "__main__":
    main()
