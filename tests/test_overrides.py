"""--set FIELD=VALUE overrides of flat config dataclasses (segmentation CLI, benchmarks)."""

import pytest

from configs.encoders import VAEConfig
from configs.overrides import field_overrides
from configs.segmentation import SegmentationConfig


def test_values_are_literals_of_the_field_type():
    got = field_overrides(SegmentationConfig, ["distractor_behind_robot=1.0", "unet_features=8",
                                               "detect_shadows=False", "distractor_max_radius=12"])
    assert got == {"distractor_behind_robot": 1.0, "unet_features": 8, "detect_shadows": False,
                   "distractor_max_radius": 12}
    assert field_overrides(VAEConfig, ["matching_one_sided=True"]) == {"matching_one_sided": True}


@pytest.mark.parametrize("item, msg", [
    ("nope=1", "--set nope: unknown field"),
    ("unet_features=8.5", "unet_features=8.5: expected a int"),
    ("unet_features=True", "unet_features=True: expected a int"),
    ("detect_shadows=true", "detect_shadows='true': expected a bool"),
    ("robot_threshold=high", "robot_threshold='high': expected a float"),
    ("sac.batch_size=8", "--set sac.\\*: SegmentationConfig has no nested configs"),
    ("unet_features", "expected KEY=VALUE"),
])
def test_bad_overrides_name_the_item(item, msg):
    with pytest.raises(ValueError, match=msg):
        field_overrides(SegmentationConfig, [item])


def test_nested_set_values_are_typed_like_flat_ones():
    from roll_jax.train import build_config

    cfg = build_config("puck_push", "roll", "smoke",
                       overrides=["sac.hidden=(64, 64)", "sac.target_entropy=None",
                                  "sac.tau=0.01", "lstm.online_schedule=((1000, 500, 2),)"])
    assert cfg.sac.hidden == (64, 64) and cfg.sac.target_entropy is None and cfg.sac.tau == 0.01
    assert cfg.lstm.online_schedule == ((1000, 500, 2),)
    for item, msg in [
        ("sac.hidden=abc", "--set sac.hidden='abc': expected a tuple\\[int, ...\\]"),
        ("sac.hidden=(64, 1.5)", "--set sac.hidden=\\(64, 1.5\\): expected a tuple\\[int, ...\\]"),
        ("sac.batch_size=big", "--set sac.batch_size='big': expected a int"),
        ("sac.target_entropy=low", "--set sac.target_entropy='low': expected a float \\| None"),
        ("lstm.online_schedule=((0, 500),)", "lstm.online_schedule=.*expected a tuple\\[tuple"),
        ("total_env_steps=lots", "--set total_env_steps='lots': expected a int"),
    ]:
        with pytest.raises(ValueError, match=msg):
            build_config("puck_push", "roll", "smoke", overrides=[item])
