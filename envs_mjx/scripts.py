"""Scripted action sequences that exercise each task's physics (tests, parity, benchmarks).

Open-loop, so the same sequence can drive MJX and C MuJoCo. Each returns float32[T, A].
"""

from __future__ import annotations

import numpy as np


def _seq(*parts) -> np.ndarray:
    return np.concatenate([np.tile(np.asarray(a, np.float32), (n, 1)) for a, n in parts])


def push_forward(n_steps: int = 30) -> np.ndarray:
    """puck_push: centre the claw behind the puck (x +0.02), then push it +y."""
    return _seq(([1.0, 0.0], 1), ([0.0, 1.0], n_steps - 1))


def hurdle_forward(n_steps: int = 30) -> np.ndarray:
    """Hurdle scenes: push the puck +y along the corridor right of the middle hurdle, stop
    before it reaches the far wall, then hold. (Driving the hand on once the puck is pinned
    against a wall squeezes it out violently, a chaotic event where MJX and C MuJoCo part.)"""
    return _seq(([0.0, 1.0], 6), ([0.0, 0.0], n_steps - 6))


def door_pull(n_steps: int = 30) -> np.ndarray:
    """door_open: lower the hook behind the handle bar, then pull it along the door's arc."""
    return _seq(([0.0, 0.0, -1.0], 6), ([0.3, -1.0, 0.0], 4), ([0.8, -1.0, 0.0], n_steps - 10))


def pickup_lift(n_steps: int = 30) -> np.ndarray:
    """pickup: open and lower onto the cube, close, then lift."""
    return _seq(([0.0, -1.0, -1.0], 8), ([0.0, 0.0, 1.0], 5), ([0.0, 1.0, 1.0], n_steps - 13))


SCRIPTS = {
    "puck_push": push_forward,
    "hurdle_bottom": hurdle_forward,
    "hurdle_top": hurdle_forward,
    "door_open": door_pull,
    "pickup": pickup_lift,
}
