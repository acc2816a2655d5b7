"""C MuJoCo twin of `Env.step`: the physics reference for parity tests and benchmarks.

It steps the very model the MJX env was built from (`env.mj_model`) with `mujoco.mj_step`,
using the same action semantics (mocap delta, hand-box clip, gripper target, substeps).
"""

from __future__ import annotations

import mujoco
import numpy as np

from envs_mjx.env import ACTION_SCALE, Env, EnvState, finger_target


class CReference:
    """One C-MuJoCo copy of an env, started from an `EnvState`."""

    def __init__(self, env: Env, state: EnvState):
        self.env = env
        self.m = env.mj_model
        self.d = mujoco.MjData(self.m)
        for name in ("qpos", "qvel", "mocap_pos", "mocap_quat", "ctrl", "act"):
            getattr(self.d, name)[:] = np.asarray(getattr(state.data, name))
        mujoco.mj_forward(self.m, self.d)
        self._low = np.asarray(env.spec.hand_low)
        self._high = np.asarray(env.spec.hand_high)

    def step(self, action) -> None:
        a = np.clip(np.asarray(action, np.float64), -1.0, 1.0)
        axes = self.env.mocap_axes
        delta = np.zeros(3)
        delta[list(axes)] = ACTION_SCALE * a[:len(axes)]
        self.d.mocap_pos[0] = np.clip(self.d.mocap_pos[0] + delta, self._low, self._high)
        if self.env.spec.kind == "pickup":
            self.d.ctrl[:] = finger_target(a[2])
        for _ in range(self.env.spec.n_substeps):
            mujoco.mj_step(self.m, self.d)

    def object_state(self) -> np.ndarray:
        adr = self.env.object_qadr
        return self.d.qpos[adr:adr + self.env.object_size].copy()

    def hand_pos(self) -> np.ndarray:
        return self.d.xpos[self.m.body("hand").id].copy()
