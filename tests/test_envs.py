"""Physics of the five scenes: pushes, walls, hand range, door, gripper, determinism, vmap,
and parity with C MuJoCo. Every rollout is T = 40 steps so each task compiles once."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import envs_mjx
from envs_mjx import scenes
from envs_mjx import tasks as tasks_mod
from envs_mjx.reference import CReference
from envs_mjx.rollout import random_actions, rollout
from envs_mjx.scripts import SCRIPTS

T = 40


@functools.lru_cache(maxsize=None)
def env_of(task):
    return envs_mjx.make(task)


@functools.lru_cache(maxsize=None)
def rollout_fn(task):
    env = env_of(task)
    return jax.jit(lambda s, a: rollout(env, s, a))


@functools.lru_cache(maxsize=None)
def place_fn(task):
    return jax.jit(env_of(task).place)


@functools.lru_cache(maxsize=None)
def reset_fn(task):
    return jax.jit(env_of(task).reset)


def run(task, state, actions):
    return rollout_fn(task)(state, jnp.asarray(actions))


# ----------------------------------------------------------------- bad input
def test_unknown_task_names_the_value_and_the_choices():
    with pytest.raises(ValueError, match=r"'puck_pull'.*puck_push.*hurdle_bottom.*pickup"):
        envs_mjx.make("puck_pull")


@pytest.mark.parametrize("bad, pattern", [
    (np.zeros(3, np.float32), r"shape \(2,\), got \(3,\)"),
    (np.zeros((1, 2), np.float32), r"shape \(2,\), got \(1, 2\)"),
    (np.zeros(2, np.int32), r"float array, got dtype int32"),
    (np.array([0.0, np.nan], np.float32), r"not finite"),
])
def test_bad_action_raises_before_stepping(bad, pattern):
    env = env_of("puck_push")
    state = place_fn("puck_push")(jnp.array([0.0, 0.5, 0.06]), jnp.array([0.0, 0.6]))
    with pytest.raises(ValueError, match=pattern):
        env.step(state, bad)


def test_bad_action_shape_is_caught_under_jit_too():
    env = env_of("door_open")
    state = reset_fn("door_open")(jax.random.PRNGKey(0))
    with pytest.raises(ValueError, match=r"'door_open'.*shape \(3,\), got \(2,\)"):
        jax.jit(env.step)(state, jnp.zeros(2))


# ----------------------------------------------------------------- physics outcomes
def test_scripted_push_moves_puck_by_hand_travel():
    env = env_of("puck_push")
    s0 = reset_fn("puck_push")(jax.random.PRNGKey(0))
    _, traj = run("puck_push", s0, SCRIPTS["puck_push"](T))
    start, end = np.asarray(env.object_state(s0)), np.asarray(traj.obj[-1])
    # The claw (radius 0.015) meets the puck (radius 0.04) 0.055 behind its centre and stops
    # at the hand box edge: the puck ends at least 0.055 ahead of it (up to 1.5 cm more where
    # the last hit sends it sliding on), pushed straight.
    ahead = end[1] - env.spec.hand_high[1]
    assert tasks_mod.PUSH_CONTACT - 0.003 < ahead < tasks_mod.PUSH_CONTACT + 0.015
    assert end[1] - start[1] > 0.09
    assert abs(end[0] - start[0]) < 0.005
    # ... and it moved monotonically forward with the hand.
    assert np.all(np.diff(np.asarray(traj.obj[:, 1])) > -1e-4)


@pytest.mark.parametrize("task, puck, wall_x", [
    # hurdle_bottom: the row y = 0.54 passes above the middle hurdle; the right wall at
    # x = 0.15 stops the puck centre at 0.15 - radius.
    ("hurdle_bottom", (-0.02, 0.54), 0.15 - scenes.PUCK_RADIUS),
    # hurdle_top: the middle hurdle spans y 0.48..0.62 at x 0.04..0.06: the puck stops at
    # x = 0.04 - radius.
    ("hurdle_top", (-0.03, 0.56), 0.04 - scenes.PUCK_RADIUS),
])
def test_walls_stop_the_puck(task, puck, wall_x):
    env = env_of(task)
    # The hand 7 cm left of the puck in its row (inside the hand box), then +x all the way.
    hand0 = (max(puck[0] - 0.07, env.spec.hand_low[0]), puck[1], env.spec.hand_low[2])
    s0 = place_fn(task)(jnp.array(hand0), jnp.array(puck))
    acts = np.tile([1.0, 0.0], (T, 1)).astype(np.float32)
    _, traj = run(task, s0, acts)
    x = np.asarray(traj.obj[:, 0])
    # the hand target kept going to the box edge, beyond the wall
    assert float(traj.mocap[-1, 0]) == pytest.approx(env.spec.hand_high[0], abs=1e-5)
    assert env.spec.hand_high[0] > wall_x + tasks_mod.PUSH_CONTACT
    assert x.max() - puck[0] > 0.02  # it was pushed ...
    # ... and never passed the wall. (Pinned there, it is squeezed out sideways: a chaotic
    # event, so only where it went along x is asserted.)
    assert x.max() < wall_x + 0.003


def test_hand_stays_in_its_range_and_state_stays_finite_on_long_random_rollouts():
    for task in envs_mjx.TASK_NAMES:
        env = env_of(task)
        low, high = np.asarray(env.spec.hand_low), np.asarray(env.spec.hand_high)
        state = reset_fn(task)(jax.random.PRNGKey(3))
        for k in range(3 if task != "puck_push" else 6):  # 120-240 random steps
            acts = random_actions(jax.random.PRNGKey(100 + k), T, env.action_size)
            state, traj = run(task, state, acts)
            mocap, hand = np.asarray(traj.mocap), np.asarray(traj.hand)
            assert np.all(mocap >= low - 1e-6) and np.all(mocap <= high + 1e-6), task
            # The hand lags its target through the soft weld and contacts: a few mm.
            assert np.all(hand >= low - 0.008) and np.all(hand <= high + 0.008), task
            leaves = [np.asarray(x) for x in jax.tree_util.tree_leaves(state.data)]
            assert all(np.isfinite(x).all() for x in leaves
                       if np.issubdtype(x.dtype, np.floating)), task


def test_goal_distance_is_the_object_distance_of_the_object_states():
    push, door = env_of("puck_push"), env_of("door_open")
    s0 = reset_fn("puck_push")(jax.random.PRNGKey(0))
    goal = place_fn("puck_push")(jnp.array(push.spec.hand_reset), jnp.array([0.03, 0.64]))
    want = np.linalg.norm(np.asarray(push.object_state(s0)) - [0.03, 0.64])
    assert float(push.goal_distance(s0, goal)) == pytest.approx(want, abs=1e-6)
    # batched object states: one distance per row; the door compares angles only
    np.testing.assert_allclose(push.object_distance(jnp.array([[3.0, 4.0], [0.0, 1.0]]),
                                                    jnp.zeros(2)), [5.0, 1.0])
    np.testing.assert_allclose(door.object_distance(jnp.array([[0.5], [0.1]]),
                                                    jnp.array([0.2])), [0.3, 0.1], rtol=1e-6)


# door_pull's phases: approach and lowering end at step 23, the pull at step 31.
DOOR_LOWERED, DOOR_RELEASED = 23, 31


def test_pulling_the_hook_opens_the_door():
    s0 = reset_fn("door_open")(jax.random.PRNGKey(0))
    _, traj = run("door_open", s0, SCRIPTS["door_open"](T))
    angle = np.asarray(traj.obj[:, 0])
    assert np.abs(angle[:DOOR_LOWERED]).max() < 0.005  # approaching and lowering: no push
    assert angle[-1] > 0.8  # pulling along the arc opens it past the largest goal angle
    assert angle.max() <= scenes.DOOR_MAX_ANGLE + 0.02  # hinge limit holds


def test_a_released_door_coasts_with_the_reference_damping_and_inertia():
    # The reference's door: hinge damping 0.1, inertia 0.244 kg m^2, no friction loss, so a
    # pushed door keeps going with time constant I / b = 2.44 s. Hand far from the door.
    env = env_of("door_open")
    s = place_fn("door_open")(jnp.asarray(tasks_mod.DOOR_REFERENCE_RESET), jnp.array([0.2]))
    w0, steps = 0.3, 10
    dof = env.mj_model.joint("door_hinge").dofadr[0]
    s = s.replace(data=s.data.replace(qvel=s.data.qvel.at[dof].set(w0)))
    _, traj = run("door_open", s, np.zeros((T, 3), np.float32))
    tau = scenes.DOOR_HINGE_INERTIA / scenes.DOOR_DAMPING
    t = steps * env.spec.n_substeps * scenes.TIMESTEP
    expected = 0.2 + w0 * tau * (1 - np.exp(-t / tau))  # 0.35 rad on
    assert float(traj.obj[steps - 1, 0]) == pytest.approx(expected, abs=0.02)


def test_door_is_reset_free():
    env = env_of("door_open")
    s0 = reset_fn("door_open")(jax.random.PRNGKey(0))
    s1, _ = run("door_open", s0, SCRIPTS["door_open"](T))
    s2 = env.reset_episode(s1, jax.random.PRNGKey(1))
    assert int(s2.t) == 0
    assert float(env.object_state(s2)[0]) == float(env.object_state(s1)[0]) > 0.5


def test_gripper_lifts_the_object_only_when_closed():
    s0 = reset_fn("pickup")(jax.random.PRNGKey(0))
    grasp = SCRIPTS["pickup"](T)
    _, traj = run("pickup", s0, grasp)
    z = np.asarray(traj.obj[:, 2])
    assert z[-1] > 0.12  # lifted ~13 cm off the table with the hand
    assert abs(float(traj.hand[-1, 2]) - scenes.GRASP_DROP - z[-1]) < 0.01
    no_grip = grasp.copy()
    no_grip[:, 2] = -1.0  # same motion, fingers kept open
    _, traj_open = run("pickup", s0, no_grip)
    assert float(traj_open.obj[-1, 2]) < scenes.CUBE_HALF + 0.005


def test_pickup_goals_hold_the_cube_in_the_air_or_leave_it_bare_on_the_table():
    """The reference's goals: 75% the cube held at the claw, the rest on the table with the
    hand elsewhere in its box, open, neither touching nor hiding it."""
    env = env_of("pickup")
    goals = jax.jit(jax.vmap(env.sample_goal))(jax.random.split(jax.random.PRNGKey(0), 128))
    cube = np.asarray(jax.vmap(env.object_state)(goals))
    hand = np.asarray(jax.vmap(env.hand_pos)(goals))
    labels = np.asarray(jax.jit(jax.vmap(lambda s: env.render_both(s)[1]))(goals))
    pixels = (labels == 2).sum((1, 2))
    table = cube[:, 2] < scenes.CUBE_HALF + 1e-4
    assert 0.15 < table.mean() < 0.35  # 25% of the goals
    grasp = hand - np.array([0.0, 0.0, scenes.GRASP_DROP])
    gap = np.linalg.norm(grasp - cube, axis=1)
    assert np.all(gap[~table] < 0.01)  # held at the claw
    assert np.all(gap[table] >= tasks_mod.PICKUP_CLEARANCE - 1e-4)
    assert np.ptp(hand[table, 1]) > 0.05 and np.ptp(hand[table, 2]) > 0.05  # spread over the box
    # A bare cube shows about as many pixels as the cube alone with the hand raised away from
    # it (+-2 with its place on the pixel grid); the fingers hide part of a held one.
    bare = env.place(jnp.array([0.0, 0.55, 0.20]), jnp.array([0.0, 0.65, scenes.CUBE_HALF]))
    alone = int((np.asarray(env.render_both(bare)[1]) == 2).sum())
    assert pixels[table].min() >= 0.8 * alone
    assert np.median(pixels[~table]) < 0.8 * alone
    # Left alone, a table goal stays put: the hand does not touch the cube.
    open_still = jnp.tile(jnp.array([0.0, 0.0, -1.0]), (5, 1))
    still = jax.jit(jax.vmap(lambda s: rollout(env, s, open_still)[1].obj[-1]))(
        jax.tree.map(lambda x: x[np.flatnonzero(table)], goals))
    assert np.abs(np.asarray(still) - cube[table]).max() < 2e-3


# ----------------------------------------------------------------- determinism / vmap
def test_same_key_same_trajectory_and_different_key_differs():
    env = env_of("hurdle_top")
    k = jax.random.PRNGKey(7)
    outs = []
    for key in (k, k, jax.random.PRNGKey(8)):
        s0 = reset_fn("hurdle_top")(key)
        _, traj = run("hurdle_top", s0, random_actions(key, T, env.action_size))
        outs.append(np.asarray(traj.obj))
    np.testing.assert_array_equal(outs[0], outs[1])
    assert not np.array_equal(outs[0], outs[2])


def test_vmapped_envs_match_single_env():
    task = "puck_push"
    env = env_of(task)
    keys = jax.random.split(jax.random.PRNGKey(11), 3)
    acts = jax.vmap(lambda k: random_actions(k, T, env.action_size))(keys)
    # Start every env next to the puck so that the random actions make contact.
    hands = jnp.array([[0.0, 0.54, 0.06], [-0.05, 0.6, 0.06], [0.05, 0.66, 0.06]])
    pucks = jnp.array([[0.0, 0.6], [0.0, 0.6], [0.0, 0.6]])
    s0 = jax.vmap(place_fn(task))(hands, pucks)
    _, batched = jax.jit(jax.vmap(lambda s, a: rollout(env, s, a)))(s0, acts)
    for i in range(3):
        si = jax.tree_util.tree_map(lambda x: x[i], s0)
        _, single = run(task, si, acts[i])
        np.testing.assert_allclose(np.asarray(batched.obj[i]), np.asarray(single.obj),
                                   atol=2e-5)
    assert float(jnp.max(jnp.abs(batched.obj[:, -1] - pucks))) > 0.01  # contact happened


# ----------------------------------------------------------------- parity with C MuJoCo
@pytest.mark.parametrize("task", envs_mjx.TASK_NAMES)
def test_mjx_matches_c_mujoco_on_scripted_actions(task):
    env = env_of(task)
    s0 = reset_fn(task)(jax.random.PRNGKey(2))
    acts = SCRIPTS[task](T)
    _, traj = run(task, s0, acts)
    ref = CReference(env, s0)
    c_obj = []
    for a in acts:
        ref.step(a)
        c_obj.append(ref.object_state())
    c_obj = np.asarray(c_obj)
    moved = np.abs(c_obj[-1] - np.asarray(env.object_state(s0))).max()
    assert moved > 0.02, "the script must move the object for the comparison to mean much"
    if task != "door_open":
        np.testing.assert_allclose(np.asarray(traj.obj), c_obj, atol=0.005)
        return
    # The door: the heavy door moves in jerks under the hook's box-box contacts, where MJX and
    # C MuJoCo part by up to 0.04 rad (8 mm at the handle) while it is pulled; released, it
    # rattles in the 16 mm between bar and hook foot and both come to rest together
    # (docs/scenes.md).
    pulled = slice(0, DOOR_RELEASED)
    np.testing.assert_allclose(np.asarray(traj.obj[pulled]), c_obj[pulled], atol=0.05)
    np.testing.assert_allclose(np.asarray(traj.obj[-1]), c_obj[-1], atol=0.03)


def _import_in_subprocess(code, pythonpath=None):
    import os
    import subprocess
    import sys

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env = {**os.environ, "JAX_PLATFORMS": "cpu"}
    if pythonpath:
        env["PYTHONPATH"] = os.pathsep.join(p for p in (pythonpath, env.get("PYTHONPATH")) if p)
    r = subprocess.run([sys.executable, "-c", code], cwd=root, env=env, capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    return r.stdout, r.stderr


def test_import_hides_only_the_missing_warp_lines(tmp_path):
    from envs_mjx.env import WARP_MISSING_LINES

    # Bare mujoco.mjx prints them (warp is not installed here): the lines still match mujoco's.
    out, _ = _import_in_subprocess("from mujoco import mjx")
    assert all(line in out.splitlines() for line in WARP_MISSING_LINES)
    out, err = _import_in_subprocess("import envs_mjx; print('imported')")
    assert out.splitlines() == ["imported"] and "Failed to import" not in err
    # A warp that is installed but broken: what it prints and mjx's report of it get through.
    (tmp_path / "warp").mkdir()
    (tmp_path / "warp" / "__init__.py").write_text(
        "print('fake warp loading')\nraise ImportError('fake warp is broken')\n")
    out, _ = _import_in_subprocess("import envs_mjx", pythonpath=str(tmp_path))
    assert "fake warp loading" in out
    assert "Failed to import warp: fake warp is broken" in out.splitlines()


# ----------------------------------------------------------------- placements and hurdle paths

def test_random_placement_puts_hand_in_its_box_and_object_in_its_region():
    env = env_of("puck_push")
    lo, hi = env.hand_bounds
    states = jax.jit(jax.vmap(env.random_placement))(*jax.random.split(jax.random.PRNGKey(0),
                                                                      (2, 64)))
    hand = np.asarray(jax.vmap(env.hand_pos)(states))
    puck = np.asarray(jax.vmap(env.object_state)(states))
    assert np.all(hand >= lo - 2e-3) and np.all(hand <= hi + 2e-3)
    (r_lo, r_hi), = env.spec.region
    assert np.all(puck >= np.asarray(r_lo) - 1e-4) and np.all(puck <= np.asarray(r_hi) + 1e-4)
    assert puck.std(0).min() > 0.01  # spread over the region, not one point


# The reference code's numbers (yufeiwang63/ROLL, vendored multiworld): mocap clip box (x, y)
# and INIT_HAND_POS of each registered push env, and the corridor sampler's segments.
REFERENCE_PUSH = {
    # SawyerPushNIPSEasy-v0: mocap_low (-0.1, 0.55), mocap_high (0.1, 0.65); INIT_HAND_POS (0, 0.4)
    "puck_push": ((-0.1, 0.55), (0.1, 0.65), (0.0, 0.4)),
    # SawyerPushHurdleMiddle-v0: (-0.15, 0.5)..(0.25, 0.65); INIT_HAND_POS (-0.1, 0.5)
    "hurdle_bottom": ((-0.15, 0.5), (0.25, 0.65), (-0.1, 0.5)),
    # SawyerPushHurdle-v0: (-0.1, 0.55)..(0.2, 0.75); INIT_HAND_POS (0, 0.4)
    "hurdle_top": ((-0.1, 0.55), (0.2, 0.75), (0.0, 0.4)),
}


@pytest.mark.parametrize("task", sorted(REFERENCE_PUSH))
def test_push_tasks_use_the_reference_hand_box_and_reset(task):
    spec = envs_mjx.TASKS[task]
    low, high, init = REFERENCE_PUSH[task]
    assert spec.hand_low[:2] == low and spec.hand_high[:2] == high
    assert "multiworld/envs/mujoco/__init__.py" in spec.source
    clipped = np.clip(init, low, high)  # where the reference's first step puts the mocap
    reset = np.asarray(spec.hand_reset[:2])
    # At that clipped target, or moved along x only as far as it takes to clear the puck.
    assert reset[1] == pytest.approx(clipped[1])
    gap = np.hypot(*np.maximum(0, np.maximum(np.asarray(spec.object_reset_low) - reset,
                                             reset - np.asarray(spec.object_reset_high))))
    assert gap >= tasks_mod.PUSH_CONTACT
    if not np.allclose(reset, clipped):
        at_clip = np.hypot(*np.maximum(0, np.maximum(np.asarray(spec.object_reset_low) - clipped,
                                                     clipped - np.asarray(spec.object_reset_high))))
        assert at_clip < tasks_mod.PUSH_CONTACT  # moved only because the target overlaps
        assert abs(reset[0] - clipped[0]) <= 0.04


def test_door_uses_the_reference_physics_and_reset():
    # SawyerDoorHookResetFreeEnv-v1: door_hook_config.xml timestep 0.003 x frame_skip 50;
    # sawyer_door_pull_hook.xml: doorjoint damping 0.1, armature 0, no frictionloss, and a
    # panel, frame and handle at default density: 0.2437 kg m^2 about the hinge (computed
    # with MuJoCo from that XML); reset-free from construction: the mocap starts at the
    # origin, clipped into the hand box (-0.1, 0.45, 0.1)..(0.05, 0.65, 0.25). The hand reset
    # is the appendix's instead (docs/scenes.md says why).
    import mujoco

    spec = envs_mjx.TASKS["door_open"]
    assert spec.n_substeps * scenes.TIMESTEP == pytest.approx(0.003 * 50)
    assert "SawyerDoorHookResetFreeEnv-v1" in spec.source
    assert spec.hand_low == (-0.1, 0.45, 0.1) and spec.hand_high == (0.05, 0.65, 0.25)
    assert tasks_mod.DOOR_REFERENCE_RESET == tuple(np.clip(0.0, spec.hand_low, spec.hand_high))
    assert spec.hand_reset == (-0.05, 0.635, 0.225)
    m = env_of("door_open").mj_model
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    full = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, full)
    dof = m.joint("door_hinge").dofadr[0]
    assert full[dof, dof] == pytest.approx(0.2437, abs=0.001)
    assert m.dof_damping[dof] == 0.1 and m.dof_frictionloss[dof] == 0.0
    assert m.dof_armature[dof] == 0.0


def _wall_gaps(task, pts):
    walls = list(scenes.OUTER_WALLS) + [scenes.MIDDLE_WALL[task]]
    return np.stack([np.hypot(np.maximum(np.abs(pts[:, 0] - cx) - hx, 0),
                              np.maximum(np.abs(pts[:, 1] - cy) - hy, 0))
                     for (cx, cy), (hx, hy) in walls], 1)


@pytest.mark.parametrize("task", sorted(scenes.MIDDLE_WALL))
def test_hurdle_pretraining_placements_cover_the_corridor_in_thirds_and_miss_every_wall(task):
    env = env_of(task)
    keys = jax.random.split(jax.random.PRNGKey(1), 3000)
    pts = np.asarray(jax.jit(jax.vmap(env.random_object_position))(keys))
    boxes = env.spec.object_region
    assert len(boxes) == 3
    member = np.stack([np.all((pts >= np.asarray(lo) - 1e-6) & (pts <= np.asarray(hi) + 1e-6), 1)
                       for lo, hi in boxes], 1)
    assert member.any(1).all()
    # a third in each segment (the reference draws a segment with p = 0.33 / 0.34 / 0.33);
    # the boxes overlap at their corners, so count by the segment each point can only be in
    only = member & (member.sum(1, keepdims=True) == 1)
    share = only.sum(0) / only.any(1).sum()
    np.testing.assert_allclose(share, 1 / 3, atol=0.05)
    assert _wall_gaps(task, pts).min() >= scenes.PUCK_RADIUS - 1e-6
    # the sampler's corners too, not only the draws
    corners = np.asarray([(x, y) for lo, hi in boxes for x in (lo[0], hi[0]) for y in (lo[1], hi[1])])
    assert _wall_gaps(task, corners).min() >= scenes.PUCK_RADIUS - 1e-9
    # and the corridor spans the way: both columns and the segment joining them
    path = np.asarray(scenes.hurdle_path(task))
    assert pts[:, 0].min() < path[0, 0] + 0.01 and pts[:, 0].max() > path[-1, 0] - 0.01


def test_object_images_with_the_hand_away_show_no_hand():
    env = env_of("hurdle_top")
    st = jax.jit(env.away_placement)(jax.random.PRNGKey(0))
    labels = np.asarray(env.render_labels(st))
    near = env.place(jnp.asarray(env.spec.hand_reset), env.object_state(st))
    assert (labels == 2).sum() > 20
    # the arm's remaining pixels are the pedestal's edge, far fewer than with the hand in its box
    assert (labels == 1).sum() < 0.5 * (np.asarray(env.render_labels(near)) == 1).sum()


@pytest.mark.parametrize("change, pattern", [
    ({"hand_reset": (0.0, 0.55, 0.06)}, r"'puck_push'.*hand reset \(0.0, 0.55\).*contact"),
    ({"hand_reset": (0.3, 0.6, 0.06)}, r"'puck_push'.*hand reset \(0.3, 0.6, 0.06\).*outside"),
    ({"hand_high": (0.1, 0.58, 0.06), "hand_reset": (-0.05, 0.55, 0.06)},
     r"'puck_push'.*cannot reach the puck goal space"),
])
def test_a_task_with_impossible_numbers_is_refused_naming_them(change, pattern):
    import dataclasses

    with pytest.raises(ValueError, match=pattern):
        dataclasses.replace(envs_mjx.TASKS["puck_push"], **change)


def test_a_pretraining_region_inside_a_wall_is_refused():
    import dataclasses

    bad = (((0.095, 0.54), (0.11, 0.65)),)  # the reference's hurdle_top column: 5 mm into the hurdle
    with pytest.raises(ValueError, match=r"'hurdle_top'.*0.095.*inside the wall"):
        dataclasses.replace(envs_mjx.TASKS["hurdle_top"], object_region=bad)


@pytest.mark.parametrize("task", sorted(scenes.MIDDLE_WALL))
def test_hurdle_path_keeps_the_puck_clear_of_every_wall(task):
    path = np.asarray(scenes.hurdle_path(task))
    # points every 5 mm along the path: the puck there touches no wall
    pts = np.concatenate([a + np.linspace(0, 1, 50)[:, None] * (b - a)
                          for a, b in zip(path[:-1], path[1:])])
    for (cx, cy), (hx, hy) in list(scenes.OUTER_WALLS) + [scenes.MIDDLE_WALL[task]]:
        gap = np.hypot(np.maximum(np.abs(pts[:, 0] - cx) - hx, 0),
                       np.maximum(np.abs(pts[:, 1] - cy) - hy, 0))
        assert gap.min() >= scenes.PUCK_RADIUS - 1e-9, ((cx, cy), gap.min())
    with pytest.raises(ValueError, match="no hurdle"):
        scenes.hurdle_path("puck_push")
