"""What the task cameras see: orientation, object centroids against a pinhole projection,
occlusion by the arm, empty scenes, other resolutions."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import envs_mjx
from envs_mjx import LABEL_OBJECT, LABEL_ROBOT
from pinhole import pinhole


@functools.lru_cache(maxsize=None)
def env_of(task, empty=False):
    env = envs_mjx.make(task)
    return env.empty_scene() if empty else env


@functools.lru_cache(maxsize=None)
def placed_view(task, empty=False, size=48):
    """jit(place -> render_both) for one task."""
    env = env_of(task, empty)

    def f(hand, obj):
        s = env.place(hand) if empty else env.place(hand, obj)
        return env.render_both(s, size, size)

    return jax.jit(f)


def view(task, hand, obj=None, empty=False, size=48):
    rgb, lab = placed_view(task, empty, size)(jnp.asarray(hand, jnp.float32),
                                              None if obj is None else jnp.asarray(obj, jnp.float32))
    return np.asarray(rgb), np.asarray(lab)


def centroid(mask):
    rows, cols = np.nonzero(mask)
    return rows.mean(), cols.mean()


FAR_HAND = (-0.18, 0.46, 0.06)


def test_push_view_is_upright_with_the_table_at_the_bottom():
    rgb, lab = view("puck_push", FAR_HAND, (0.0, 0.6))
    assert rgb.dtype == np.uint8 and rgb.shape == (48, 48, 3)
    assert lab.dtype == np.int32 and lab.shape == (48, 48)
    bottom = rgb[-3:].reshape(-1, 3).astype(int)
    # Table colour (0.72, 0.62, 0.48): red above blue on every bottom pixel, no labels there.
    assert np.all(bottom[:, 0] > bottom[:, 2] + 20) and np.all(lab[-3:] == 0)
    # The arm reaches in from the far side of the table: above the puck in the image.
    assert centroid(lab == LABEL_ROBOT)[0] < centroid(lab == LABEL_OBJECT)[0]
    # Puck is blue.
    puck_rgb = rgb[lab == LABEL_OBJECT].astype(int)
    assert np.all(puck_rgb[:, 2] > puck_rgb[:, 0] + 40)


@pytest.mark.parametrize("task, hand, positions, top_offset", [
    # puck xy; the visible part of the puck is mostly its top face at z = 0.03.
    ("puck_push", FAR_HAND, [(0.0, 0.6), (0.1, 0.6), (-0.1, 0.55), (0.0, 0.68)],
     (0.0, 0.0, 0.03)),
    # pickup: the cube is drawn as a sphere centred on the object position (side view).
    ("pickup", (0.0, 0.55, 0.2), [(0.0, 0.65, 0.02), (0.0, 0.58, 0.02), (0.0, 0.62, 0.10)],
     (0.0, 0.0, 0.0)),
])
def test_object_centroid_follows_the_pinhole_projection(task, hand, positions, top_offset):
    env = env_of(task)
    for pos in positions:
        _, lab = view(task, hand, pos)
        mask = lab == LABEL_OBJECT
        assert mask.sum() >= 4, (task, pos)
        point = np.array(list(pos) + [0.0] * (3 - len(pos))) + np.array(top_offset)
        if task == "puck_push":
            point[2] = top_offset[2]
        row, col = pinhole(env.camera, point, 48, 48)
        r, c = centroid(mask)
        assert abs(r - row) < 1.5 and abs(c - col) < 1.5, (task, pos, (r, c), (row, col))


def test_object_moves_the_right_way_in_the_image():
    _, lab0 = view("puck_push", FAR_HAND, (0.0, 0.6))
    _, lab_x = view("puck_push", FAR_HAND, (0.08, 0.6))
    _, lab_y = view("puck_push", FAR_HAND, (0.0, 0.68))
    r0, c0 = centroid(lab0 == LABEL_OBJECT)
    rx, cx = centroid(lab_x == LABEL_OBJECT)
    ry, cy = centroid(lab_y == LABEL_OBJECT)
    # The push camera looks from the far side (+y) back towards the robot (azimuth 270):
    # world +x is image left, world +y (towards the camera) is image down.
    assert cx < c0 - 3 and abs(rx - r0) < 1.5
    assert ry > r0 + 3 and abs(cy - c0) < 1.5
    # Pickup (side view from +x): +y is image right, +z is image up.
    _, p0 = view("pickup", (0.0, 0.55, 0.2), (0.0, 0.6, 0.02))
    _, p_up = view("pickup", (0.0, 0.55, 0.2), (0.0, 0.6, 0.10))
    _, p_y = view("pickup", (0.0, 0.55, 0.2), (0.0, 0.64, 0.02))
    assert centroid(p_up == LABEL_OBJECT)[0] < centroid(p0 == LABEL_OBJECT)[0] - 3
    assert centroid(p_y == LABEL_OBJECT)[1] > centroid(p0 == LABEL_OBJECT)[1] + 3


def test_arm_above_the_puck_hides_it():
    puck = (0.0, 0.6)
    _, clear = view("puck_push", FAR_HAND, puck)
    # Hand just past the puck on the camera side: the wrist and forearm cross the line of
    # sight to the puck (no contact: 0.1 m > puck radius + claw radius).
    _, hidden = view("puck_push", (0.0, 0.70, 0.06), puck)
    visible_before = clear == LABEL_OBJECT
    visible_after = hidden == LABEL_OBJECT
    assert visible_after.sum() < 0.5 * visible_before.sum()
    # The pixels the puck lost now show the robot.
    lost = visible_before & ~visible_after
    assert np.mean(hidden[lost] == LABEL_ROBOT) > 0.9


def test_empty_scene_has_no_object_and_same_background():
    hand = (0.05, 0.6, 0.06)
    rgb, lab = view("hurdle_top", hand, (-0.03, 0.58))
    rgb_e, lab_e = view("hurdle_top", hand, empty=True)
    assert (lab == LABEL_OBJECT).sum() > 10 and not np.any(lab_e == LABEL_OBJECT)
    same = lab != LABEL_OBJECT
    np.testing.assert_array_equal(rgb[same], rgb_e[same])
    empty = env_of("hurdle_top", True)
    with pytest.raises(ValueError, match="no object"):
        empty.object_state(jax.jit(empty.place)(jnp.array(hand)))


def test_video_resolution_and_bad_size():
    rgb, lab = view("door_open", (-0.05, 0.635, 0.225), (0.3,), size=128)
    assert rgb.shape == (128, 128, 3) and lab.shape == (128, 128)
    assert (lab == LABEL_OBJECT).sum() > 100 and (lab == LABEL_ROBOT).sum() > 100
    with pytest.raises(ValueError, match="width must be a positive int, got 0"):
        env_of("door_open").renderer(0, 48)


@pytest.mark.parametrize("task", envs_mjx.TASK_NAMES)
def test_every_task_shows_robot_and_object_at_reset(task):
    env = env_of(task)
    s = jax.jit(env.reset)(jax.random.PRNGKey(0))
    _, lab = jax.jit(env.render_both)(s)
    lab = np.asarray(lab)
    assert (lab == LABEL_ROBOT).sum() >= 10, task
    assert (lab == LABEL_OBJECT).sum() >= 10, task
