"""Trajectory replay: ring insertion, latent refresh, HER relabeling vs a NumPy reference."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from roll_jax.agents import replay, skewfit

CAP, T, HW, A, DS, DG = 6, 5, 8, 2, 3, 2
FRACS = (0.2, 0.5, 0.3)


def _trajs(e, first_id):
    """E episodes whose every entry encodes (episode id, step) so slots can be identified."""
    ids = np.arange(first_id, first_id + e, dtype=np.float32)
    steps = np.arange(T + 1, dtype=np.float32)
    rng = np.random.default_rng(first_id)
    img = (ids[:, None] * 10 + steps[None]).astype(np.uint8)[:, :, None, None, None]
    return replay.Trajectory(
        images=jnp.broadcast_to(jnp.asarray(img), (e, T + 1, HW, HW, 3)),
        object_images=jnp.broadcast_to(jnp.asarray(img + 100), (e, T + 1, HW, HW, 3)),
        actions=jnp.asarray(ids[:, None, None] + np.zeros((e, T, A), np.float32)),
        obs_latents=jnp.asarray(rng.normal(size=(e, T + 1, DS)), jnp.float32),
        frame_latents=jnp.asarray(rng.normal(size=(e, T + 1, DG)), jnp.float32),
        goal_latents=jnp.asarray(rng.normal(size=(e, T + 1, DG)), jnp.float32),
        rollout_goals=jnp.asarray(rng.normal(size=(e, DG)), jnp.float32),
    )


def _buffer():
    return replay.init_buffer(CAP, T, (HW, HW, 3), A, DS, DG)


# Jitted once: eager op-by-op dispatch costs more than compiling on this CPU.
add = jax.jit(replay.add_trajectories)
draw = jax.jit(replay.draw_indices, static_argnums=2)
sample_images = jax.jit(skewfit.sample_images, static_argnums=2)


def test_ring_insertion_wraps_and_size_saturates():
    buf = _buffer()
    assert buf.capacity == CAP and buf.horizon == T
    buf = add(buf, _trajs(4, 0))  # ids 0..3 -> slots 0..3
    assert int(buf.size) == 4 and int(buf.insert_pos) == 4
    buf = add(buf, _trajs(4, 4))  # ids 4..7 -> slots 4, 5, 0, 1
    assert int(buf.size) == CAP and int(buf.insert_pos) == 2
    np.testing.assert_array_equal(buf.actions[:, 0, 0], [6, 7, 2, 3, 4, 5])
    np.testing.assert_array_equal(buf.images[:, 3, 0, 0, 0], np.array([6, 7, 2, 3, 4, 5]) * 10 + 3)
    buf = add(buf, _trajs(3, 8))  # ids 8..10 -> slots 2, 3, 4
    assert int(buf.size) == CAP and int(buf.insert_pos) == 5
    np.testing.assert_array_equal(buf.actions[:, 0, 0], [6, 7, 8, 9, 10, 5])
    t = _trajs(2, 20)
    np.testing.assert_array_equal(add(buf, t).rollout_goals[5], t.rollout_goals[0])
    with pytest.raises(ValueError, match="capacity"):
        replay.add_trajectories(buf, _trajs(CAP + 1, 0))
    with pytest.raises(ValueError, match="actions"):
        replay.add_trajectories(buf, t.replace(actions=jnp.zeros((2, T + 1, A))))


def test_recompute_updates_filled_slots_only():
    buf = add(_buffer(), _trajs(4, 0))
    sentinel = -7.0
    buf = buf.replace(obs_latents=jnp.full_like(buf.obs_latents, sentinel),
                      goal_latents=jnp.full_like(buf.goal_latents, sentinel))

    def obs_enc(imgs):  # [T+1, H, W, 3] -> [T+1, DS]: mean pixel, repeated
        m = jnp.mean(imgs.astype(jnp.float32), axis=(1, 2, 3))
        return jnp.repeat(m[:, None], DS, axis=1)

    def goal_enc(imgs):  # whole episode -> running mean over time (needs the trajectory)
        m = jnp.mean(imgs.astype(jnp.float32), axis=(1, 2, 3))
        run = jnp.cumsum(m) / jnp.arange(1, T + 2)
        return jnp.stack([run, -run], axis=1)

    # chunk = 4 does not divide CAP = 6: blocks of 3 slots (the largest divisor), the second
    # one partly filled.
    @jax.jit
    def refresh(b):
        b = replay.recompute(b, "obs_latents", obs_enc, b.images, 4)
        return replay.recompute(b, "goal_latents", goal_enc, b.object_images, 4)

    new = refresh(buf)
    px = np.asarray(buf.images[..., 0, 0, 0], np.float32)  # [CAP, T+1]
    np.testing.assert_allclose(new.obs_latents[:4], np.repeat(px[:4, :, None], DS, 2), rtol=1e-6)
    opx = np.asarray(buf.object_images[..., 0, 0, 0], np.float32)
    run = np.cumsum(opx, axis=1) / np.arange(1, T + 2)
    np.testing.assert_allclose(new.goal_latents[:4], np.stack([run, -run], -1)[:4], rtol=1e-6)
    assert np.all(np.asarray(new.obs_latents[4:]) == sentinel)
    assert np.all(np.asarray(new.goal_latents[4:]) == sentinel)
    np.testing.assert_array_equal(new.images, buf.images)


def test_map_filled_skips_empty_blocks_and_keeps_their_values():
    """Slots past `size` keep `old`, also in a block that is skipped whole (size 2 of 6,
    blocks of 3); fn takes a pytree of per-episode arrays."""
    src = (jnp.arange(6.0), 10 * jnp.arange(6.0))
    old = jnp.full((6,), -1.0)
    for size, want in ((2, [10, 21, -1, -1, -1, -1]), (4, [10, 21, 32, 43, -1, -1]),
                       (6, [10, 21, 32, 43, 54, 65])):
        got = jax.jit(lambda s: replay.map_filled(lambda e: e[0] + e[1] + 10, src, old, s, 3))(
            jnp.int32(size))
        np.testing.assert_array_equal(np.asarray(got), np.asarray(want, np.float32))


def _reference(buf, idx, prior_goals, fracs):
    """Plain NumPy, one sample at a time."""
    b = len(idx.t)
    n_r, n_p = round(fracs[0] * b), round(fracs[1] * b)
    gl, rg = np.asarray(buf.goal_latents), np.asarray(buf.rollout_goals)
    out = {k: [] for k in ("obs", "goal", "action", "reward", "next_obs")}
    for i in range(b):
        j, t, f = int(idx.traj[i]), int(idx.t[i]), int(idx.future_t[i])
        g = rg[j] if i < n_r else (np.asarray(prior_goals[i]) if i < n_r + n_p else gl[j, f])
        out["goal"].append(g)
        out["obs"].append(np.asarray(buf.obs_latents[j, t]))
        out["next_obs"].append(np.asarray(buf.obs_latents[j, t + 1]))
        out["action"].append(np.asarray(buf.actions[j, t]))
        out["reward"].append(-np.sum((gl[j, t + 1] - g) ** 2))
    return {k: np.stack(v) for k, v in out.items()}


def test_her_relabeling_matches_numpy_reference():
    buf = add(_buffer(), _trajs(4, 0))  # 4 of 6 slots filled
    b = 50
    key = jax.random.key(3)
    prior = jax.random.normal(jax.random.key(4), (b, DG))
    batch = jax.jit(replay.sample_transitions, static_argnums=(2, 4))(buf, key, b, prior, FRACS)
    idx = draw(buf, key, b)  # the same draws sample_transitions made
    traj, t, ft = (np.asarray(x) for x in (idx.traj, idx.t, idx.future_t))
    assert traj.min() >= 0 and traj.max() < 4  # only stored episodes
    assert t.min() >= 0 and t.max() < T
    assert np.all(ft > t) and np.all(ft <= T)
    ref = _reference(buf, idx, prior, FRACS)
    for k, v in ref.items():
        np.testing.assert_allclose(getattr(batch, k), v, rtol=1e-5, atol=1e-6, err_msg=k)
    np.testing.assert_array_equal(batch.done, 0.0)
    # The reference code's reward: the norm, not its square.
    l2 = jax.jit(replay.sample_transitions, static_argnums=(2, 4, 5))(buf, key, b, prior, FRACS,
                                                                       "l2")
    np.testing.assert_allclose(l2.reward, -np.sqrt(-ref["reward"]), rtol=1e-5, atol=1e-6)
    # Exact counts by source: rollout rows equal their episode's rollout goal, etc.
    n_r, n_p, n_f = replay.goal_counts(b, FRACS)
    assert (n_r, n_p, n_f) == (10, 25, 15)
    g = np.asarray(batch.goal)
    rg = np.asarray(buf.rollout_goals)[traj]
    fg = np.asarray(buf.goal_latents)[traj, ft]
    is_r = np.all(g == rg, axis=1)
    is_p = np.all(g == np.asarray(prior), axis=1)
    is_f = np.all(g == fg, axis=1)
    assert is_r[:n_r].all() and is_p[n_r:n_r + n_p].all() and is_f[n_r + n_p:].all()
    assert is_r.sum() == n_r and is_p.sum() == n_p and is_f.sum() == n_f


def test_future_steps_cover_range():
    buf = add(_buffer(), _trajs(CAP, 0))
    idx = draw(buf, jax.random.key(0), 4000)
    t, ft = np.asarray(idx.t), np.asarray(idx.future_t)
    assert np.all(ft > t) and np.all(ft <= T)
    # Uniform on (t, T]: for t = 0 every step 1..T appears with ~equal frequency.
    counts = np.bincount(ft[t == 0], minlength=T + 1)[1:]
    assert counts.min() > 0.6 * counts.mean()
    assert set(np.unique(np.asarray(idx.traj))) == set(range(CAP))


def test_goal_counts_exact():
    assert replay.goal_counts(1024, FRACS) == (205, 512, 307)
    assert sum(replay.goal_counts(7, FRACS)) == 7
    assert replay.goal_counts(10, (1.0, 0.0, 0.0)) == (10, 0, 0)


def test_sample_trajectories_and_images():
    buf = add(_buffer(), _trajs(3, 0))
    tr = jax.jit(replay.sample_trajectories, static_argnums=2)(buf, jax.random.key(0), 16)
    ids = np.asarray(tr.actions[:, 0, 0])
    assert tr.images.shape == (16, T + 1, HW, HW, 3) and tr.object_images.dtype == jnp.uint8
    assert set(ids.astype(int)) <= {0, 1, 2}
    np.testing.assert_array_equal(tr.images[:, :, 0, 0, 0], ids[:, None] * 10 + np.arange(T + 1))
    np.testing.assert_array_equal(tr.rollout_goals, np.asarray(buf.rollout_goals)[ids.astype(int)])
    # Uniform images: only filled slots.
    imgs = sample_images(buf, jax.random.key(1), 200)
    px = np.asarray(imgs[:, 0, 0, 0])
    assert imgs.shape == (200, HW, HW, 3) and set(px // 10) <= {0, 1, 2}
    # Skewed: all weight on (episode 1, step 4) plus weight on an unfilled slot (never drawn).
    w = jnp.zeros((CAP, T + 1)).at[1, 4].set(1.0).at[5, 0].set(100.0)
    imgs = sample_images(buf, jax.random.key(2), 50, skewfit.weights_cdf(w, buf.size))
    np.testing.assert_array_equal(imgs[:, 0, 0, 0], 14)
    # Proportional: weights 3:1 between two images.
    w = jnp.zeros((CAP, T + 1)).at[0, 0].set(3.0).at[2, 5].set(1.0)
    px = np.asarray(sample_images(buf, jax.random.key(3), 4000,
                                  skewfit.weights_cdf(w, buf.size))[:, 0, 0, 0])
    assert set(px) == {0, 25} and abs(np.mean(px == 0) - 0.75) < 0.03
