"""Physics of the five scenes: pushes, walls, hand range, door, gripper, determinism, vmap,
and parity with C MuJoCo. Every rollout is T = 40 steps so each task compiles once."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import envs_mjx
from envs_mjx import scenes
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
    # at the hand box edge y = 0.75: the puck must end 0.055 ahead of it, pushed straight.
    expected = 0.75 + scenes.PUCK_RADIUS + 0.015
    assert end[1] - start[1] == pytest.approx(expected - start[1], abs=0.006)
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
    hand0 = env.spec.hand_reset
    s0 = place_fn(task)(jnp.array(hand0), jnp.array(puck))
    # Go left of the puck, down to its row, then push +x all the way to the hand box edge.
    rows = int(round((puck[1] - hand0[1]) / 0.02))
    acts = np.concatenate([np.tile([-1.0, 0.0], (3, 1)), np.tile([0.0, 1.0], (rows, 1)),
                           np.tile([1.0, 0.0], (T - 3 - rows, 1))]).astype(np.float32)
    _, traj = run(task, s0, acts)
    end = np.asarray(traj.obj[-1])
    assert float(traj.mocap[-1, 0]) == pytest.approx(0.2, abs=1e-5)  # hand target kept going
    assert end[0] - puck[0] > 0.02  # it was pushed ...
    assert end[0] < wall_x + 0.003  # ... and stopped by the wall, not the hand box


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


def test_pulling_the_hook_opens_the_door():
    s0 = reset_fn("door_open")(jax.random.PRNGKey(0))
    _, traj = run("door_open", s0, SCRIPTS["door_open"](T))
    angle = np.asarray(traj.obj[:, 0])
    assert angle[5] < 0.02  # lowering the hook alone does not move the door
    assert angle[-1] > 0.8  # pulling along the arc opens it past the largest goal angle
    assert angle[-1] <= scenes.DOOR_MAX_ANGLE + 0.02  # hinge limit holds


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
    np.testing.assert_allclose(np.asarray(traj.obj), c_obj, atol=0.005)


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

def test_random_placement_puts_hand_in_its_box_and_object_in_the_goal_space():
    env = env_of("puck_push")
    lo, hi = env.hand_bounds
    states = jax.jit(jax.vmap(env.random_placement))(*jax.random.split(jax.random.PRNGKey(0),
                                                                      (2, 64)))
    hand = np.asarray(jax.vmap(env.hand_pos)(states))
    puck = np.asarray(jax.vmap(env.object_state)(states))
    assert np.all(hand >= lo - 2e-3) and np.all(hand <= hi + 2e-3)
    assert np.all(puck >= np.asarray(env.spec.object_goal_low) - 1e-4)
    assert np.all(puck <= np.asarray(env.spec.object_goal_high) + 1e-4)
    assert puck.std(0).min() > 0.01  # spread over the goal space, not one point


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
