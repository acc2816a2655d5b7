"""The five tasks' numbers: horizons, hand ranges, resets, goal spaces and cameras.

Sources: the paper's appendix "Simulated task details" (wins for goal/reset spaces) and
multiworld (the reference code's environments). Deviations are explained in docs/scenes.md.
"""

from __future__ import annotations

import dataclasses

from envs_mjx.render import Camera
from envs_mjx.scenes import HAND_Z_PUSH

Vec = tuple[float, ...]

PUSH_CAMERA = Camera(lookat=(0.0, 0.85, 0.2), distance=0.3, elevation=-45.0, azimuth=270.0)
# Door: multiworld's camera (lookat (-0.2, 0.55, 0.6), distance 0.25, elevation -60, azimuth
# 360) looks along +x, i.e. along the plane of our closed door, which it would see edge-on.
# We look diagonally from the robot's left-front instead, so that door face, handle, hook and
# the hand's whole range are in view at every angle (docs/scenes.md shows both states).
DOOR_CAMERA = Camera(lookat=(-0.05, 0.55, 0.15), distance=0.6, elevation=-45.0, azimuth=45.0)
PICKUP_CAMERA = Camera(lookat=(0.0, 0.67, 0.1), distance=0.7, elevation=0.0, azimuth=180.0)


@dataclasses.dataclass(frozen=True)
class TaskSpec:
    """Static description of one task. Coordinates in metres, angles in radians."""

    name: str
    kind: str  # "push" | "door" | "pickup": selects the scene builder and object model
    action_size: int
    horizon: int
    camera: Camera
    hand_low: Vec  # mocap clip box (x, y, z); a fixed coordinate has low == high
    hand_high: Vec
    hand_reset: Vec
    hand_goal_low: Vec
    hand_goal_high: Vec
    object_goal_low: Vec
    object_goal_high: Vec
    object_reset_low: Vec  # the object is reset uniformly in this box (low == high: fixed)
    object_reset_high: Vec
    reset_free: bool = False


# Push tasks: multiworld's hand box [-0.1, 0.1] x [0.55, 0.65] is the hand *goal/state* box of
# the appendix; the reset (-0.02, 0.5) lies outside it, so the mocap clip box must be larger
# (multiworld's is too). Ours contains the reset and lets the hand reach every side of the
# puck goal space (puck radius 0.04 + claw radius 0.015).
_PUSH_HAND_LOW = (-0.2, 0.45, HAND_Z_PUSH)
_PUSH_HAND_HIGH = (0.2, 0.75, HAND_Z_PUSH)
_PUSH_HAND_RESET = (-0.02, 0.5, HAND_Z_PUSH)
# Hurdles: the appendix's hand reset (-0.02, 0.5) is 4 cm from the hurdle_bottom puck reset
# (-0.02, 0.54), inside puck radius + claw radius (0.055): it would start in contact. The
# hand starts 2 cm further back instead, clear of every puck reset.
_HURDLE_HAND_RESET = (-0.02, 0.48, HAND_Z_PUSH)

TASKS: dict[str, TaskSpec] = {
    "puck_push": TaskSpec(
        name="puck_push", kind="push", action_size=2, horizon=50, camera=PUSH_CAMERA,
        hand_low=_PUSH_HAND_LOW, hand_high=_PUSH_HAND_HIGH, hand_reset=_PUSH_HAND_RESET,
        hand_goal_low=(-0.1, 0.55), hand_goal_high=(0.1, 0.65),
        object_goal_low=(-0.15, 0.5), object_goal_high=(0.15, 0.7),
        object_reset_low=(0.0, 0.6), object_reset_high=(0.0, 0.6),
    ),
    "hurdle_bottom": TaskSpec(
        name="hurdle_bottom", kind="push", action_size=2, horizon=50, camera=PUSH_CAMERA,
        hand_low=_PUSH_HAND_LOW, hand_high=_PUSH_HAND_HIGH, hand_reset=_HURDLE_HAND_RESET,
        hand_goal_low=(-0.025, 0.6), hand_goal_high=(0.0, 0.65),
        object_goal_low=(0.1, 0.55), object_goal_high=(0.11, 0.65),
        object_reset_low=(-0.02, 0.54), object_reset_high=(-0.02, 0.54),
    ),
    "hurdle_top": TaskSpec(
        name="hurdle_top", kind="push", action_size=2, horizon=50, camera=PUSH_CAMERA,
        hand_low=_PUSH_HAND_LOW, hand_high=_PUSH_HAND_HIGH, hand_reset=_HURDLE_HAND_RESET,
        hand_goal_low=(-0.03, 0.54), hand_goal_high=(0.0, 0.6),
        object_goal_low=(0.1, 0.55), object_goal_high=(0.11, 0.6),
        object_reset_low=(-0.04, 0.55), object_reset_high=(-0.02, 0.63),
    ),
    "door_open": TaskSpec(
        name="door_open", kind="door", action_size=3, horizon=100, camera=DOOR_CAMERA,
        hand_low=(-0.1, 0.45, 0.1), hand_high=(0.05, 0.65, 0.25), hand_reset=(-0.05, 0.635, 0.225),
        hand_goal_low=(-0.1, 0.45, 0.1), hand_goal_high=(0.05, 0.65, 0.25),
        object_goal_low=(0.0,), object_goal_high=(0.83,),
        object_reset_low=(0.0,), object_reset_high=(0.0,),
        reset_free=True,
    ),
    # Pickup: the appendix gives a 10 cm (y) x 13 cm (z) state/goal box for hand and object;
    # multiworld's z range [0.05, 0.13] is 8 cm and excludes the hand reset z = 0.2, so the
    # hand box is [0.07, 0.20] (13 cm, contains the reset; at z = 0.07 the fingers reach the
    # cube on the table) and the object box is 5 cm lower: z in [0.02, 0.15].
    "pickup": TaskSpec(
        name="pickup", kind="pickup", action_size=3, horizon=50, camera=PICKUP_CAMERA,
        hand_low=(0.0, 0.55, 0.07), hand_high=(0.0, 0.65, 0.20), hand_reset=(0.0, 0.6, 0.2),
        hand_goal_low=(0.0, 0.55, 0.07), hand_goal_high=(0.0, 0.65, 0.20),
        object_goal_low=(0.0, 0.55, 0.02), object_goal_high=(0.0, 0.65, 0.15),
        object_reset_low=(0.0, 0.6, 0.02), object_reset_high=(0.0, 0.6, 0.02),
    ),
}

PICKUP_AIR_GOAL_FRACTION = 0.75  # appendix: 75% of evaluation goals in the air
