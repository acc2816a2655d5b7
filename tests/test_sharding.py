"""Seed sharding over 2 (forced host) devices gives the same training as one device.

The device count of a JAX process is fixed at start-up, so the runs happen in one subprocess
with XLA_FLAGS=--xla_force_host_platform_device_count=2: a 4-seed, 1-chunk run sharded over
both devices (2 seeds each), then the same run unsharded (devices=1); metrics and the final
checkpointed state must agree, and each run resumes on the other device count. Both runs load
the same untrained segmentation and encoders (fresh initialisations saved as checkpoints):
sharding does not care what they learned, and fitting them here would repeat test_train's
segmentation and pre-training compiles.

Not bit-exact: XLA:CPU's 2-device program computes one MJX `env.step` within a float32 ulp of
the 1-device one (`env.reset` and SAC updates alone are exact; `shard_map` instead of jit
shardings differs the same way), and 100 steps of training amplify that to <1e-2 relative in
the metrics and a few flipped replay pixels. Single parameter leaves can differ far more: Adam
moves a weight whose gradient is near zero by about lr * sign(gradient), so a rounding flip of
that sign moves a near-zero bias by a large fraction of its norm (measured up to 48% on one
CPU, 2% on another). So the final state is compared per part (policy, critics, each optimiser
state, each replay field, ...) against the distance to the nearest other seed's part, which is
what a sharding bug (another seed's key or rows) gives. 2 seeds per device, not 1: a vmapped
convolution of batch 1 compiles to another kernel (more roundoff, same story).
"""

import json
import os
import re
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from roll_jax.training import sharding

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

SCRIPT = textwrap.dedent("""
    import dataclasses, json, os, sys, time
    import jax
    jax.config.update("jax_compilation_cache_dir", sys.argv[2])
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)
    import numpy as np
    import orbax.checkpoint as ocp
    from jax.sharding import PartitionSpec as P
    from configs.segmentation import segmentation_config
    from configs.train import make_config
    from roll_jax.encoders import pretrain
    from roll_jax.training import driver, loop, run_dir, sharding
    from roll_jax.training.state import init_state
    from roll_jax.segmentation import pipeline

    assert jax.device_count() == 2, jax.devices()
    base = sys.argv[1]
    report = {}
    report["all_for_3_seeds"] = len(sharding.resolve("all", 3))  # largest divisor: 1
    try:
        sharding.resolve(2, 3)
    except ValueError as e:
        report["indivisible"] = str(e)

    # Toy check of the placement itself: state split, outputs pinned, frozen replicated.
    sh = sharding.make("all", 2)
    f = sh.wrap_chunk(jax.jit(jax.vmap(lambda s, fr, p: (s + fr * p, s.sum()),
                                       in_axes=(0, None, None))))
    st, m = f(sh.shard(np.arange(8.0).reshape(2, 4)), sh.replicate(np.float32(2.0)), 3.0)
    report["toy"] = {"seed_sharded": st.sharding.spec == P("seeds"), "shards": [list(s.data.shape)
                     for s in st.addressable_shards], "value": np.asarray(st).tolist(),
                     "metric": np.asarray(m).tolist()}

    # The seed map on sharded seeds (each device maps over its own 2, one at a time): same
    # values as a plain vmap, and no cross-device communication in the compiled program.
    fn = lambda s, fr: (s * fr + s.sum(), s.sum())
    sh4, x4 = sharding.make("all", 4), np.arange(16.0).reshape(4, 4)
    mapped = jax.jit(sharding.over_seeds(fn, 4, 2, 1))
    v, m = mapped(sh4.shard(x4), 2.0)
    hlo = mapped.lower(sh4.shard(x4), 2.0).compile().as_text()
    report["map_toy"] = {"value": np.asarray(v).tolist(), "metric": np.asarray(m).tolist(),
                         "collectives": [op for op in ("all-gather", "all-to-all",
                                                       "collective-permute", "all-reduce")
                                         if op in hlo]}

    # Untrained segmentation and encoders; one 100-step chunk of 2 envs per seed, SAC learning
    # from step 50, the LSTM trained in the chunk.
    seg = segmentation_config("puck_push", "smoke", n_frames=300, unet_epochs=2, eval_states=8)
    base_cfg = make_config("puck_push", "roll", "smoke", n_eval_goals=2, segmentation=seg)
    cfg = make_config("puck_push", "roll", "smoke", seeds=4, n_envs=2, epoch_env_steps=100,
                      total_env_steps=100, n_eval_goals=2, segmentation=seg,
                      sac=dataclasses.replace(base_cfg.sac, learning_starts=50),
                      lstm=dataclasses.replace(base_cfg.lstm, online_schedule=((2**62, 100, 2),)),
                      # No online scene-VAE training: Adam's first steps move its near-zero
                      # head weights by about lr * sign(gradient), so float32 roundoff between
                      # the two programs can flip a latent dimension; nothing to do with
                      # placement, which is what this compares.
                      vae_schedule="none")
    given = {"seg_ckpt": os.path.join(base, "segmentation"), "enc_ckpt": os.path.join(base, "encoders")}
    pipeline.save(given["seg_ckpt"], "puck_push",
                  pipeline.initial_params(48, 48, 3, seg, jax.random.PRNGKey(1)), seg)
    pretrain.save(given["enc_ckpt"], cfg, pretrain.initial(cfg, jax.random.PRNGKey(2)))
    seen = []
    compile_chunk = loop.compile_chunk

    def recording(cfg, env, *placement, **kw):
        chunk = compile_chunk(cfg, env, *placement, **kw)

        def call(state, frozen, plan):
            leaves = [x for x in jax.tree.leaves(state) if x.size]
            seen.append({
                "seed_sharded": all(getattr(x.sharding, "spec", None) == P("seeds")
                                    for x in leaves),
                "devices": sorted({len(x.sharding.device_set) for x in leaves}),
                "frozen_replicated": all(getattr(x.sharding, "spec", None) == P()
                                         for x in jax.tree.leaves(frozen))})
            return chunk(state, frozen, plan)
        return call

    loop.compile_chunk = recording
    out = {}
    for name, devices in (("sharded", "all"), ("single", 1)):
        d = os.path.join(base, name)
        t0 = time.time()
        rows = driver.run(cfg, d, progress=False, devices=devices, **given)
        ck = ocp.StandardCheckpointer()
        state = ck.restore(os.path.abspath(os.path.join(d, "ckpt", "1", "default")))
        ck.close()
        np.savez(os.path.join(base, name + ".npz"), **{k: np.asarray(v) for k, v in state.items()})
        with open(os.path.join(d, run_dir.COMPLETE_MARKER)) as fh:
            marker = json.load(fh)
        out[name] = {"rows": rows, "seen": seen[-1], "marker": marker,
                     "wall_s": round(time.time() - t0, 1)}
    report["runs"] = out
    import envs_mjx
    pre = pretrain.initial(cfg, jax.random.PRNGKey(2))
    abstract = jax.eval_shape(lambda k: init_state(k, cfg, envs_mjx.make("puck_push"),
                                                  pre.scene_vae, pre.lstm),
                              jax.random.PRNGKey(0))
    # The checkpoint's keys index all leaves (empty ones are not saved).
    report["leaf_paths"] = [jax.tree_util.keystr(p) for p, _ in
                            jax.tree_util.tree_flatten_with_path(abstract)[0]]
    # Each finished run resumed on the other device count: its checkpoint restores there
    # (nothing left to train: no chunk is compiled).
    report["cross_resume"] = {
        name: driver.run(cfg, os.path.join(base, name), resume=True, progress=False,
                        devices=devices, **given)
        for name, devices in (("sharded", 1), ("single", "all"))}
    print("REPORT " + json.dumps(report))
    with open(os.path.join(base, "report.json"), "w") as fh:
        json.dump(report, fh)
""")


@pytest.fixture(scope="module")
def two_device_runs(tmp_path_factory):
    base = tmp_path_factory.mktemp("sharding")
    flags = f"{os.environ.get('XLA_FLAGS', '')} --xla_force_host_platform_device_count=2"
    env = dict(os.environ, XLA_FLAGS=flags.strip(), JAX_PLATFORMS="cpu", MUJOCO_GL="disable")
    proc = subprocess.run([sys.executable, "-c", SCRIPT, str(base), os.path.join(ROOT, ".jax_cache")],
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=1800,
                          check=False)
    lines = [line for line in proc.stdout.splitlines() if line.startswith("REPORT ")]
    assert proc.returncode == 0 and lines, proc.stderr[-4000:]
    return base, json.loads(lines[-1][len("REPORT "):])


def test_indivisible_seeds_rejected(two_device_runs):
    _, report = two_device_runs
    assert "--seeds 3 is not divisible by the 2 devices" in report["indivisible"]
    assert report["all_for_3_seeds"] == 1  # 'all' never refuses: it uses the devices that fit


def test_placement(two_device_runs):
    _, report = two_device_runs
    toy = report["toy"]
    assert toy["seed_sharded"]
    assert toy["shards"] == [[1, 4], [1, 4]]
    np.testing.assert_array_equal(toy["value"], np.arange(8.0).reshape(2, 4) + 6.0)
    assert toy["metric"] == [6.0, 22.0]
    sharded, single = report["runs"]["sharded"], report["runs"]["single"]
    assert sharded["seen"]["seed_sharded"] and sharded["seen"]["frozen_replicated"]
    assert sharded["seen"]["devices"] == [2]
    assert single["seen"]["devices"] == [1] and not single["seen"]["seed_sharded"]
    assert sharded["marker"]["devices"] == 2 and single["marker"]["devices"] == 1
    # CPU 'auto': each device runs its seeds one at a time (sharding.over_seeds)
    assert sharded["marker"]["seed_batch"] == single["marker"]["seed_batch"] == 1
    x = np.arange(16.0).reshape(4, 4)
    np.testing.assert_array_equal(report["map_toy"]["value"], x * 2 + x.sum(1, keepdims=True))
    np.testing.assert_array_equal(report["map_toy"]["metric"], x.sum(1))
    assert report["map_toy"]["collectives"] == []


def test_sharded_equals_unsharded(two_device_runs):
    base, report = two_device_runs
    a, b = report["runs"]["sharded"]["rows"], report["runs"]["single"]["rows"]
    assert len(a) == len(b) == 8  # 4 seeds x evaluations at 0 and 100 env steps
    assert all(r["q_loss"] > 0 and r["lstm_loss"] > 0 for r in a[4:])  # SAC and LSTM did learn
    for ra, rb in zip(a, b):
        assert ra.keys() == rb.keys()
        for k in ra:
            np.testing.assert_allclose(ra[k], rb[k], rtol=0.05, atol=1e-6, err_msg=k)
    finals = [r["final_distance"] for r in b[4:]]
    assert len(set(finals)) == len(finals)  # the seeds differ (a swap would show above)
    sa, sb = np.load(base / "sharded.npz"), np.load(base / "single.npz")
    assert sorted(sa.files) == sorted(sb.files)
    groups = {}
    for k in sa.files:
        x, y = sa[k], sb[k]
        assert x.shape == y.shape and x.dtype == y.dtype, k
        if x.dtype.kind != "f":  # replay images, indices, counters
            assert np.mean(x != y) <= 1e-4, k
            continue
        groups.setdefault(_group(report["leaf_paths"][int(k)]), []).append(k)
    n_seeds = len(finals)
    for name, keys in groups.items():
        x = np.stack([np.concatenate([sa[k][s].ravel() for k in keys]) for s in range(n_seeds)])
        y = np.stack([np.concatenate([sb[k][s].ravel() for k in keys]) for s in range(n_seeds)])
        x, y = x.astype(np.float64), y.astype(np.float64)
        for s in range(n_seeds):
            diff, norm = np.linalg.norm(x[s] - y[s]), np.linalg.norm(y[s])
            # How far this seed's state is from the nearest other seed's: what a sharding bug
            # (another seed's key or rows) would give. The relative floor covers parts that
            # all seeds share (the pre-trained LSTM, goal latents).
            between = min(np.linalg.norm(y[s] - y[t]) for t in range(n_seeds) if t != s)
            assert diff <= 0.25 * between + 1e-3 * norm, (name, s, diff, between, norm)


def _group(path):
    """'.sac.policy_params[...]' -> '.sac.policy_params'; '.buffer.actions' stays."""
    return re.match(r"(\.\w+)(\.\w+|\[\d+\])?", path).group(0)


def test_resume_on_other_device_count(two_device_runs):
    _, report = two_device_runs
    for name, rows in report["cross_resume"].items():
        assert rows == report["runs"][name]["rows"], name


@pytest.mark.parametrize("seeds,n_devices,seed_batch", [(4, 1, 1), (4, 1, 2), (4, 1, None),
                                                         (6, 2, 1), (6, 1, 3), (8, 2, 2)])
def test_over_seeds_runs_every_seed_in_place(seeds, n_devices, seed_batch):
    """Mapped, vmapped or both, per device: each seed's result lands in its own row, exactly
    as a plain vmap (elementwise math: no rounding difference), shared args un-batched."""
    import jax
    import jax.numpy as jnp

    def one(state, scale):
        return {"x": state["x"] * scale + state["i"]}, jnp.sum(state["x"]) + state["i"]

    state = {"x": jnp.arange(seeds * 3, dtype=jnp.float32).reshape(seeds, 3),
             "i": jnp.arange(seeds, dtype=jnp.float32) * 100}
    want = jax.vmap(one, in_axes=(0, None))(state, 2.0)
    got = jax.jit(sharding.over_seeds(one, seeds, n_devices, seed_batch))(state, 2.0)
    jax.tree.map(np.testing.assert_array_equal, got, want)


def test_resolve_seed_batch():
    assert sharding.resolve_seed_batch("auto", 6, 1, platform="cpu") == 1
    assert sharding.resolve_seed_batch("auto", 6, 2, platform="gpu") == 3  # all of a device's
    assert sharding.resolve_seed_batch("2", 8, 2) == 2
    with pytest.raises(ValueError, match="--seed-batch 2 does not divide the 3 seed"):
        sharding.resolve_seed_batch(2, 6, 2)
    for bad in ("0", "many", -2):
        with pytest.raises(ValueError, match="'auto' or a positive integer"):
            sharding.parse_seed_batch(bad)


def test_resolve_single_process():
    """This process has one CPU device: 'all' is it; asking for more fails with both numbers."""
    import jax

    n = jax.device_count()
    assert len(sharding.resolve("all", n)) == n
    assert sharding.make(1, 3) is None
    with pytest.raises(ValueError, match=f"--devices {n + 1}: only {n} device"):
        sharding.resolve(str(n + 1), 2 * (n + 1))
    for bad in ("0", "two", -1):
        with pytest.raises(ValueError, match="'all' or a positive integer"):
            sharding.parse_devices(bad)


def test_cli_checks_devices_before_compiling(tmp_path, capsys):
    from roll_jax.training import cli

    out = str(tmp_path / "run")
    with pytest.raises(SystemExit):
        cli.parse_args(["--seeds", "3", "--devices", "2", "--out", out])
    assert "--devices 2: only 1 device(s) available" in capsys.readouterr().err
    a, cfg, _ = cli.parse_args(["--seeds", "3", "--devices", "1", "--out", out])
    assert a.devices == "1" and cfg.seeds == 3 and not os.path.exists(out)
    with pytest.raises(SystemExit):
        cli.parse_args(["--seeds", "3", "--seed-batch", "2", "--out", out])
    assert "--seed-batch 2 does not divide the 3 seed(s)" in capsys.readouterr().err
