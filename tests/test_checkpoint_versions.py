"""Encoder checkpoints of an earlier format or earlier task numbers are refused on load, each
with the reason (no restore is attempted: the meta is read first)."""

import pytest

from configs.train import make_config
from roll_jax.common.checkpoint import write_meta
from roll_jax.encoders import pretrain


@pytest.mark.parametrize("version, pattern", [
    (2, r"earlier task numbers.*hand box.*pretrain them again"),
    (1, r"version 1.*beta / batch"),
])
def test_encoders_of_an_earlier_version_are_refused_saying_why(tmp_path, version, pattern):
    cfg = make_config("hurdle_bottom", "roll", "smoke")
    meta = {**pretrain._meta(cfg), "version": version}
    write_meta(str(tmp_path / "encoders"), meta)
    with pytest.raises(ValueError, match=pattern):
        pretrain.load(str(tmp_path / "encoders"), cfg)


def test_the_current_version_passes_the_meta_check_and_reaches_the_restore(tmp_path):
    cfg = make_config("hurdle_bottom", "roll", "smoke")
    write_meta(str(tmp_path / "encoders"), pretrain._meta(cfg))
    # The meta matches, so load goes on to restore the (absent) arrays: not a version error.
    with pytest.raises(Exception) as e:
        pretrain.load(str(tmp_path / "encoders"), cfg)
    assert "this code needs" not in str(e.value) and "task numbers" not in str(e.value)


def test_encoders_of_an_earlier_task_revision_are_refused_naming_the_task(tmp_path):
    cfg = make_config("pickup", "roll", "smoke")
    meta = {k: v for k, v in pretrain._meta(cfg).items() if k != "task_revision"}  # revision 1
    write_meta(str(tmp_path / "encoders"), meta)
    with pytest.raises(ValueError, match=r"revision 1 of task 'pickup'.*revision 2.*pretrain"):
        pretrain.load(str(tmp_path / "encoders"), cfg)
