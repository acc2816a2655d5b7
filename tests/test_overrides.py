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
    ("nope=1", "--set nope: unknown field of SegmentationConfig. Valid: n_frames, "),
    ("unet_feature=8", "--set unet_feature: unknown field of SegmentationConfig; did you mean "
                       "unet_features\\? Valid: n_frames, "),
    ("unet_features=8.5", "--set unet_features: SegmentationConfig.unet_features takes int, "
                          "got 8.5 \\(float\\)"),
    ("unet_features=True", "takes int, got True \\(bool\\)"),
    ("detect_shadows=true", "takes bool, got 'true' \\(str\\) \\(Python literals: True, False\\)"),
    ("robot_threshold=high", "robot_threshold: SegmentationConfig.robot_threshold takes float, "
                             "got 'high'"),
    ("sac.batch_size=8", "--set sac.\\*: SegmentationConfig has no nested configs"),
    ("unet_features", "expected KEY=VALUE"),
])
def test_bad_overrides_name_the_item(item, msg):
    with pytest.raises(ValueError, match=msg):
        field_overrides(SegmentationConfig, [item])


def test_nested_set_values_are_typed_like_flat_ones():
    from configs.train import build_config

    cfg = build_config("puck_push", "roll", "smoke",
                       overrides=["sac.hidden=(64, 64)", "sac.target_entropy=None",
                                  "sac.tau=0.01", "lstm.online_schedule=((1000, 500, 2),)"])
    assert cfg.sac.hidden == (64, 64) and cfg.sac.target_entropy is None and cfg.sac.tau == 0.01
    assert cfg.lstm.online_schedule == ((1000, 500, 2),)
    for item, msg in [
        ("sac.hidden=abc", "--set sac.hidden: SACConfig.hidden takes tuple\\[int, ...\\], "
                           "got 'abc'"),
        ("sac.hidden=(64, 1.5)", "--set sac.hidden: .* takes tuple\\[int, ...\\], "
                                 "got \\(64, 1.5\\)"),
        ("sac.batch_size=big", "--set sac.batch_size: SACConfig.batch_size takes int, got 'big' "
                               "\\(str\\)"),
        ("sac.batchsize=8", "--set sac.batchsize: unknown field of SACConfig; did you mean "
                            "sac.batch_size\\? Valid: hidden, "),
        ("sca.batch_size=8", "--set sca.batch_size: unknown config group; did you mean sac\\? "
                             "Valid: segmentation, scene_vae, object_vae, lstm, sac"),
        ("sac=(64, 64)", "--set sac=\\(64, 64\\): sac is a group of fields \\(SACConfig\\); set "
                         "one of them: --set sac.FIELD=VALUE"),
        ("sac.target_entropy=low", "--set sac.target_entropy: .* takes float \\| None, got 'low'"),
        ("lstm.online_schedule=((0, 500),)", "lstm.online_schedule: .* takes tuple\\[tuple"),
        ("total_env_steps=lots", "--set total_env_steps: TrainConfig.total_env_steps takes int, "
                                 "got 'lots'"),
        ("seeds=3", "--set seeds: given by the command's --seeds, not --set"),
    ]:
        with pytest.raises(ValueError, match=msg):
            build_config("puck_push", "roll", "smoke", overrides=[item])
