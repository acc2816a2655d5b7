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
