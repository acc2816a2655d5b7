"""Unknown-object segmentation config (paper appendix "Details on unknown object segmentation")."""

from __future__ import annotations

import dataclasses

from configs import presets


@dataclasses.dataclass(frozen=True)
class SegmentationConfig:
    # Background model: random actions in the object-free scene.
    n_frames: int = 2000  # Appendix B.1: 2000 images (push tasks); 4000 for door/pickup (per-task file)
    var_threshold: float = 16.0  # Appendix B.1: OpenCV's default ("automatically chosen")
    detect_shadows: bool = True  # OpenCV default; shadows count as foreground in `segment`
    n_mixtures: int = 5  # OpenCV default
    # MOG2 background ratio used only to LABEL the robot for the U-Net (ours; not in the paper).
    # OpenCV's 0.9 absorbs arm parts that occupy a pixel >10% of the time into the background,
    # so the same arm is labelled robot in one pose and not in another; a lower ratio labels
    # the whole arm (robot-label recall at 0.9 / 0.5: door_open 34% / 79%, pickup 33% / 67%;
    # precision >= 92%).
    # `segment` always uses the model's own ratio (0.9). See docs/segmentation.md.
    label_background_ratio: float = 0.9
    n_envs: int = 40  # parallel random walks from random hand positions (ours; covers the hand box)
    # Robot U-Net.
    unet_features: int = 16  # not in the paper (ours): 16..128 wide; 64 is milesial's, 16x the CPU cost; per task below
    unet_epochs: int = 30  # Appendix B.1
    unet_lr: float = 1e-3  # Appendix B.1
    unet_momentum: float = 0.9  # Appendix B.1 (Nesterov)
    unet_weight_decay: float = 5e-4  # Appendix B.1
    unet_batch_size: int = 8  # not in the paper (ours): small batches, many SGD steps at lr 1e-3
    distractor_prob: float = 0.5  # not in the paper: share of training images with a pasted distractor
    # Not in the paper: share of distractors centred on a robot pixel (the object touching or in
    # front of the arm) and their largest radius in px at 48x48.
    distractor_near_robot: float = 0.0
    distractor_max_radius: float = 8.0
    # Not in the paper: share of distractors drawn behind the arm (painted on not-robot pixels
    # only): the U-Net otherwise only sees the arm against the empty scene's table and wall.
    distractor_behind_robot: float = 0.0
    robot_threshold: float = 0.5  # U-Net probability above which a pixel is robot (per task)
    # Evaluation.
    eval_states: int = 500  # ours: >= 500 random states with a visible object

    def __post_init__(self):
        for name in ("n_frames", "n_envs", "unet_features", "unet_epochs", "unet_batch_size",
                     "eval_states"):
            if getattr(self, name) <= 0:
                raise ValueError(f"SegmentationConfig.{name} must be positive, got {getattr(self, name)}")
        if not 0.0 < self.robot_threshold < 1.0:
            raise ValueError(f"SegmentationConfig.robot_threshold must be in (0, 1), got {self.robot_threshold}")
        if not 0.0 < self.label_background_ratio <= 1.0:
            raise ValueError("SegmentationConfig.label_background_ratio must be in (0, 1], got "
                             f"{self.label_background_ratio}")
        if not 0.0 <= self.distractor_near_robot <= 1.0:
            raise ValueError("SegmentationConfig.distractor_near_robot must be in [0, 1], got "
                             f"{self.distractor_near_robot}")
        if not 0.0 <= self.distractor_behind_robot <= 1.0:
            raise ValueError("SegmentationConfig.distractor_behind_robot must be in [0, 1], got "
                             f"{self.distractor_behind_robot}")
        if not self.distractor_max_radius >= 1.5:
            raise ValueError("SegmentationConfig.distractor_max_radius must be >= 1.5 px, got "
                             f"{self.distractor_max_radius}")
        if not 0.0 <= self.distractor_prob <= 1.0:
            raise ValueError(f"SegmentationConfig.distractor_prob must be in [0, 1], got {self.distractor_prob}")


# Appendix B.1 records 2000 frames for puck pushing; 4000 for the other tasks (ours).
_N_FRAMES = {"puck_push": 2000, "hurdle_bottom": 2000, "hurdle_top": 2000, "door_open": 4000,
             "pickup": 4000}
# Per-task U-Net probability threshold (our calibration, see docs/segmentation.md).
_ROBOT_THRESHOLD: dict[str, float] = {"puck_push": 0.3, "hurdle_bottom": 0.1, "hurdle_top": 0.1,
                                      "pickup": 0.2, "door_open": 0.3}
# Per-task U-Net width: the width each task's targets were measured with (docs/segmentation.md);
# the others use the default 16.
_UNET_FEATURES: dict[str, int] = {"hurdle_bottom": 8, "hurdle_top": 8, "pickup": 8}
# Per-task robot-label background ratio (our calibration, see docs/segmentation.md).
_LABEL_BACKGROUND_RATIO: dict[str, float] = {"door_open": 0.5, "pickup": 0.5}
# Per-task distractor placement (our calibration, see docs/segmentation.md): the door camera
# sees the gripper in front of the door, which the empty scene never shows, so door distractors
# are large, mostly centred on the arm, and always drawn behind it. pickup's goal images hold
# the cube between the fingers, where the empty scene only ever shows fingers: cube-sized
# distractors, all centred on the arm, teach the U-Net that a blob there is not robot.
_DISTRACTORS: dict[str, dict] = {
    "door_open": {"distractor_prob": 0.7, "distractor_near_robot": 0.7,
                  "distractor_max_radius": 12.0, "distractor_behind_robot": 1.0},
    "pickup": {"distractor_prob": 0.7, "distractor_near_robot": 1.0,
               "distractor_max_radius": 4.0},
}


def segmentation_config(task: str, preset: str = "paper", **overrides) -> SegmentationConfig:
    """The task's segmentation config for a preset, with keyword overrides."""
    if task not in _N_FRAMES:
        raise ValueError(f"unknown task {task!r}; expected one of {', '.join(_N_FRAMES)}")
    pre = presets.get(preset)
    values = {"n_frames": _N_FRAMES[task]}
    if task in _ROBOT_THRESHOLD:
        values["robot_threshold"] = _ROBOT_THRESHOLD[task]
    if task in _UNET_FEATURES:
        values["unet_features"] = _UNET_FEATURES[task]
    values.update(_DISTRACTORS.get(task, {}))
    if task in _LABEL_BACKGROUND_RATIO:
        values["label_background_ratio"] = _LABEL_BACKGROUND_RATIO[task]
    values.update(pre.for_task("segmentation", task))
    values.update(overrides)
    return SegmentationConfig(**values)
