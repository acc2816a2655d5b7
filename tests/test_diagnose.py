"""The diagnosis's path geometry and its Spearman parts, against hand computations."""

import numpy as np
import pytest

from roll_jax.analysis import diagnose


def test_path_distance_follows_the_corridor_not_the_straight_line():
    path = diagnose.task_path("hurdle_bottom")  # left column, joining segment, goal column
    goal = np.asarray(diagnose.GOALS["hurdle_bottom"])
    start = path[1]  # the corner where the start column meets the joining segment
    want = np.linalg.norm(path[2] - path[1]) + abs(goal[1] - path[2][1])
    assert diagnose.path_distance(path, start, goal)[0] == pytest.approx(want, abs=1e-9)
    assert want > np.linalg.norm(goal - start) + 0.03  # round the corner, not across it
    pts = diagnose.path_points(path, 0.01)
    gaps = np.linalg.norm(np.diff(pts, axis=0), axis=1)  # each segment cut in equal parts
    assert gaps.min() > 0.009 and gaps.max() < 0.011
    with pytest.raises(ValueError, match="door_open"):
        diagnose.task_path("door_open")


def test_profile_spearman_splits_the_path_at_8_cm_and_at_the_reset():
    pd = np.arange(0, 31, 1.0)  # cm
    latent = np.where(pd <= 20, pd, 40 - pd)  # rises to 20 cm, then falls
    res = diagnose.profile_spearman({"path_cm": pd, "latent": latent, "reset_path_cm": 20.0})
    assert res["spearman_on_the_way"] == pytest.approx(1.0)
    assert res["spearman_within_8cm"] == pytest.approx(1.0)
    assert res["spearman"] < 0.9 and res["spearman_beyond_8cm"] < 0.5


class _Encoder:
    """A goal encoder on 2-d latents: frame latent = mean pixel per channel pair; its
    `sequence` either passes each frame through or holds the last non-empty frame."""

    def __init__(self, holds: bool):
        self.holds = holds

    def frame_latents(self, frozen, scene_params, images):
        import jax.numpy as jnp

        return jnp.mean(images, axis=(-3, -2))[..., :2]

    def single(self, lstm_params, z):
        return z

    def sequence(self, lstm_params, z):
        import jax
        import jax.numpy as jnp

        if not self.holds:
            return z

        def step(held, x):
            held = jnp.where(jnp.any(x != 0), x, held)
            return held, held

        return jax.lax.scan(step, jnp.zeros_like(z[0]), z)[1]


def test_occlusion_scores_the_empty_image_and_the_lstm_memory():
    pd = np.array([0.0, 5.0, 10.0, 20.0])  # cm
    # the goal at (0.3, 0.4): the empty image's latent (0, 0) is 0.5 away; the visible puck's
    # are 0.1, 0.2, 0.6 and 0.9 away
    path = {"profile": {"path_cm": pd}, "goal_frame_latent": np.array([0.3, 0.4]),
            "visible_latents": np.array([[0.3, 0.5], [0.3, 0.6], [0.3, -0.2], [1.2, 0.4]])}
    forgets = diagnose.occlusion(_Encoder(holds=False), None, None, None, path)
    assert forgets["empty_latent_distance"] == pytest.approx(0.5)
    assert forgets["share_of_path_worse_than_empty"] == pytest.approx(0.5)  # 0.6, 0.9 > 0.5
    assert forgets["visible_beats_empty_within_cm"] == 5.0
    assert forgets["memory_first_hidden_frame"] == pytest.approx(0.0, abs=1e-6)
    holds = diagnose.occlusion(_Encoder(holds=True), None, None, None, path)
    assert holds["memory_last_hidden_frame"] == pytest.approx(1.0, abs=1e-6)
    assert len(holds["memory_per_hidden_frame"]) == diagnose.OCC_HIDDEN


def test_pickup_grasp_profile_measures_what_lowering_the_claw_earns():
    from roll_jax.analysis.diagnose_pickup import grasp_profile

    cube = np.zeros((30, 2))
    cube[13:, 1] = np.linspace(0.0, 0.12, 17)  # lifted from step 14 on
    goal = np.array([0.0, 0.12])
    honest = np.linalg.norm(cube - goal, axis=1)[:, None]  # a latent that is the cube's height
    res = grasp_profile(honest, np.zeros(1), cube, goal, first_close=8)
    assert res["spearman"] == pytest.approx(1.0)
    assert res["lower_share"] == pytest.approx(0.0) and res["close_penalty_share"] == pytest.approx(0.0)
    hiding = honest.copy()
    hiding[4:8] -= 0.06  # the open claw over the cube looks half-way lifted, closing undoes it
    res = grasp_profile(hiding, np.zeros(1), cube, goal, first_close=8)
    assert res["lower_share"] == pytest.approx(0.5) and res["close_penalty_share"] == pytest.approx(0.5)
    with pytest.raises(ValueError, match="does not fall"):
        grasp_profile(honest[::-1], np.zeros(1), cube, goal, first_close=8)


def test_pickup_prior_goals_are_matched_to_the_nearest_goal_latent():
    from roll_jax.analysis.diagnose_pickup import prior_goals

    z_goals = np.array([[0.0], [1.0], [2.0]])
    cube = np.array([[0.6, 0.02], [0.6, 0.10], [0.6, 0.12]])  # one on the table, two in the air
    res = prior_goals(np.array([[0.1], [0.9], [2.2], [5.0]]), z_goals, cube)
    assert res["share_nearest_in_air"] == pytest.approx(0.75)
    assert res["goal_spacing_median"] == pytest.approx(1.0)
    assert res["nearest_goal_distance_median"] == pytest.approx(0.15)


def test_pickup_grasp_phases_are_read_from_the_actions():
    from roll_jax.analysis.diagnose_pickup import grasp_phases

    actions = np.zeros((20, 3))
    actions[:5, 2] = -1.0  # open while lowering
    actions[5:, 2] = 1.0  # closes from step 5
    actions[:5, 1] = -1.0  # down, then still, then up from step 9
    actions[9:, 1] = 1.0
    assert grasp_phases(actions) == (5, 9)


def test_door_exploration_counts_the_episodes_that_open_the_door(tmp_path):
    import json

    from roll_jax.analysis import diagnose

    out = tmp_path / "d.json"
    diagnose.main(["--task", "door_open", "--n", "8", "--out", str(out)])
    res = json.loads(out.read_text())["random_episodes"]
    assert set(res) == {"task reset", "reference reset"}
    for r in res.values():
        assert r["n"] == 8 and 0.0 <= r["opened_0.2"] <= r["opened_0.05"] <= 1.0
    # from right above the gap, lowering the hook and drifting -y opens the door in some
    above = res["task reset"]
    assert above["hand"] == [-0.05, 0.635, 0.225]
    assert above["opened_0.05"] > 0 and above["mean_widest_rad"] > 0.01


def test_state_r2_scores_each_state_on_the_axes_the_hand_box_spans():
    import envs_mjx

    rng = np.random.default_rng(0)
    door, push = envs_mjx.make("door_open"), envs_mjx.make("puck_push")
    hand = rng.uniform(door.spec.hand_low, door.spec.hand_high, (200, 3))
    angle = rng.uniform(0.0, 1.0, (200, 1))
    mix = rng.normal(size=(3, 8))
    # latents that hold the hand (mixed into 8 dims) but not the door
    res = diagnose._state_r2(door, hand @ mix, hand, angle)
    assert res["hand_axes"] == "xyz" and res["hand_r2"] > 0.99
    assert len(res["hand_r2_per_axis"]) == 3 and min(res["hand_r2_per_axis"]) > 0.99
    # latents that hold only the hand's x: x alone is located
    x_only = diagnose._state_r2(door, hand[:, :1] @ mix[:1], hand, angle)["hand_r2_per_axis"]
    assert x_only[0] > 0.99 and max(x_only[1:]) < 0.1
    assert res["door_angle_r2"] < 0.1 and res["door_angle_std"] == [round(float(angle.std()), 4)]
    both = diagnose._state_r2(door, np.concatenate([hand @ mix, angle], 1), hand, angle)
    assert both["door_angle_r2"] > 0.99
    puck = rng.uniform(-0.1, 0.1, (200, 2))
    res = diagnose._state_r2(push, np.concatenate([hand[:, :2], puck], 1), hand, puck)
    assert res["hand_axes"] == "xy" and res["hand_r2"] > 0.99 and res["puck_r2"] > 0.99
