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
