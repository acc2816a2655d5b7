"""Scripted action sequences that exercise each task's physics (tests, parity, benchmarks).

Open-loop, so the same sequence can drive MJX and C MuJoCo. Each returns float32[T, A].
"""

from __future__ import annotations

import numpy as np


def _seq(*parts) -> np.ndarray:
    return np.concatenate([np.tile(np.asarray(a, np.float32), (n, 1)) for a, n in parts])


def push_forward(n_steps: int = 30) -> np.ndarray:
    """puck_push: from the reset beside the puck, centre the claw behind it (x +0.03), then
    push it +y to the hand box's far edge."""
    return _seq(([0.75, 0.0], 2), ([0.0, 1.0], n_steps - 2))


def hurdle_bottom_forward(n_steps: int = 30) -> np.ndarray:
    """hurdle_bottom: from the reset on the puck's -x side, line up with the puck's row, push
    it +x along the corridor towards the goal column, stop before the wall, then hold.
    (Driving the hand on once the puck is pinned against a wall squeezes it out violently, a
    chaotic event where MJX and C MuJoCo part.)"""
    return _seq(([0.0, 1.0], 2), ([1.0, 0.0], 6), ([0.0, 0.0], n_steps - 8))


def hurdle_top_forward(n_steps: int = 30) -> np.ndarray:
    """hurdle_top: from the reset right of the puck, go round it (+y, then -x above it), push
    it -y down its column, stop before the wall, then hold."""
    return _seq(([0.0, 1.0], 9), ([-1.0, 0.0], 3), ([0.0, -1.0], 6), ([0.0, 0.0], n_steps - 18))


# door_open: above the gap behind the handle bar (the hook stem 5 mm clear of the bar).
DOOR_ABOVE_GAP = (-0.05, 0.645, 0.226)
DOOR_APPROACH_STEPS = (7, 10)  # rise (x, z), then move over the gap (y)


def door_approach(hand_reset) -> tuple:
    """The (action, steps) phases from `hand_reset` to `DOOR_ABOVE_GAP`: x and z first (clear
    of the bar), then y; 17 steps from any reset in the hand box."""
    from envs_mjx.env import ACTION_SCALE

    rise, move = DOOR_APPROACH_STEPS
    d = (np.asarray(DOOR_ABOVE_GAP) - np.asarray(hand_reset)) / ACTION_SCALE
    return (([d[0] / rise, 0.0, d[2] / rise], rise), ([0.0, d[1] / move, 0.0], move))


def door_pull(n_steps: int = 40) -> np.ndarray:
    """door_open: from the task's hand reset over the gap behind the handle bar
    (`door_approach`, 17 steps), lower the hook behind the bar, pull it along the door's arc,
    then hold still (the hook in the gap between bar and panel stops the coasting door)."""
    from envs_mjx.tasks import TASKS

    return _seq(*door_approach(TASKS["door_open"].hand_reset), ([0.0, 0.0, -1.0], 6),
                ([0.3, -1.0, 0.0], 4), ([0.8, -1.0, 0.0], 4), ([0.0, 0.0, 0.0], n_steps - 31))


def pickup_lift(n_steps: int = 30) -> np.ndarray:
    """pickup: open and lower onto the cube, close, then lift."""
    return _seq(([0.0, -1.0, -1.0], 8), ([0.0, 0.0, 1.0], 5), ([0.0, 1.0, 1.0], n_steps - 13))


SCRIPTS = {
    "puck_push": push_forward,
    "hurdle_bottom": hurdle_bottom_forward,
    "hurdle_top": hurdle_top_forward,
    "door_open": door_pull,
    "pickup": pickup_lift,
}
