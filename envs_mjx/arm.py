"""A Sawyer-like arm from primitives: MJCF fragment and closed-form inverse kinematics.

The chain is yaw (z) -> shoulder pitch -> elbow pitch -> wrist pitch -> hand twist (z).
Five hinges are exactly enough to hold the hand at any reachable position with a fixed,
downward orientation, which is what the mocap weld asks for (as in multiworld, where
the real Sawyer's 7 joints follow a welded mocap body). The links are visual only
(they must be seen and occlude the object); only the hand's end effector collides.
"""

from __future__ import annotations

import jax.numpy as jnp

# Shoulder position (world) and link lengths (m). The base stands behind the table's
# near edge (table spans y 0.2..1.2), like the Sawyer's pedestal in multiworld.
SHOULDER = (0.0, 0.15, 0.30)
UPPER_LEN = 0.35
FORE_LEN = 0.35
WRIST_DROP = 0.10  # wrist pitch axis sits this far above the hand frame origin
N_ARM_JOINTS = 5

ROBOT_RED = "0.62 0.09 0.08 1"
ROBOT_DARK = "0.16 0.16 0.18 1"
ROBOT_GREY = "0.55 0.56 0.58 1"


def arm_xml(hand_geoms: str, hand_extra_bodies: str = "") -> str:
    """MJCF of pedestal + articulated arm; `hand_geoms` are placed in the `hand` body.

    The hand frame origin is the end-effector point the mocap target drives.
    """
    sx, sy, sz = SHOULDER
    # Joints get armature and damping so the weld-driven chain is well conditioned
    # and does not oscillate with the coarse 10 ms timestep.
    joint = 'type="hinge" armature="0.02" damping="2" limited="false"'
    return f"""
    <body name="pedestal" pos="{sx} {sy} 0">
      <geom name="pedestal_col" type="cylinder" pos="0 0 -0.2" size="0.07 0.4" rgba="{ROBOT_DARK}" contype="0" conaffinity="0" group="1"/>
    </body>
    <body name="arm_base" pos="{sx} {sy} {sz}">
      <inertial pos="0 0 0" mass="0.5" diaginertia="0.005 0.005 0.005"/>
      <joint name="j0_yaw" axis="0 0 1" {joint}/>
      <geom name="base_head" type="cylinder" size="0.065 0.05" rgba="{ROBOT_RED}" contype="0" conaffinity="0" group="1"/>
      <body name="upper_arm" pos="0 0 0">
        <inertial pos="0 {UPPER_LEN / 2} 0" mass="0.3" diaginertia="0.003 0.001 0.003"/>
        <joint name="j1_shoulder" axis="1 0 0" {joint}/>
        <geom name="shoulder_knob" type="cylinder" size="0.055 0.05" euler="0 90 0" rgba="{ROBOT_DARK}" contype="0" conaffinity="0" group="1"/>
        <geom name="upper_link" type="capsule" fromto="0 0 0 0 {UPPER_LEN} 0" size="0.045" rgba="{ROBOT_RED}" contype="0" conaffinity="0" group="1"/>
        <body name="fore_arm" pos="0 {UPPER_LEN} 0">
          <inertial pos="0 {FORE_LEN / 2} 0" mass="0.2" diaginertia="0.002 0.0005 0.002"/>
          <joint name="j2_elbow" axis="1 0 0" {joint}/>
          <geom name="elbow_knob" type="cylinder" size="0.045 0.045" euler="0 90 0" rgba="{ROBOT_DARK}" contype="0" conaffinity="0" group="1"/>
          <geom name="fore_link" type="capsule" fromto="0 0 0 0 {FORE_LEN} 0" size="0.035" rgba="{ROBOT_RED}" contype="0" conaffinity="0" group="1"/>
          <body name="wrist" pos="0 {FORE_LEN} 0">
            <inertial pos="0 0 -0.05" mass="0.1" diaginertia="0.0005 0.0005 0.0005"/>
            <joint name="j3_wrist" axis="1 0 0" {joint}/>
            <geom name="wrist_knob" type="cylinder" size="0.035 0.035" euler="0 90 0" rgba="{ROBOT_DARK}" contype="0" conaffinity="0" group="1"/>
            <geom name="wrist_link" type="capsule" fromto="0 0 0 0 0 {-WRIST_DROP + 0.035}" size="0.03" rgba="{ROBOT_GREY}" contype="0" conaffinity="0" group="1"/>
            <body name="hand" pos="0 0 {-WRIST_DROP}">
              <inertial pos="0 0 0" mass="0.1" diaginertia="0.0005 0.0005 0.0005"/>
              <joint name="j4_twist" axis="0 0 1" {joint}/>
              {hand_geoms}
              {hand_extra_bodies}
            </body>
          </body>
        </body>
      </body>
    </body>
    <body name="mocap" mocap="true" pos="0 0.6 0.1"/>
    """


WELD_XML = '<weld body1="mocap" body2="hand" solref="0.02 1" relpose="0 0 0 1 0 0 0"/>'


def arm_ik(hand_pos):
    """Joint angles [5] that put the hand frame at `hand_pos` (3,), pointing down.

    Elbow-up solution; jnp so that goal states can be built inside jit/vmap.
    """
    hand_pos = jnp.asarray(hand_pos, jnp.float32)
    dx = hand_pos[0] - SHOULDER[0]
    dy = hand_pos[1] - SHOULDER[1]
    dz = hand_pos[2] + WRIST_DROP - SHOULDER[2]
    q0 = jnp.arctan2(-dx, dy)  # yaw about z maps +y onto (-sin q0, cos q0)
    r = jnp.sqrt(dx * dx + dy * dy)
    d2 = r * r + dz * dz
    cos_q2 = (d2 - UPPER_LEN**2 - FORE_LEN**2) / (2 * UPPER_LEN * FORE_LEN)
    q2 = -jnp.arccos(jnp.clip(cos_q2, -1.0, 1.0))  # negative: elbow above the wrist
    q1 = jnp.arctan2(dz, r) - jnp.arctan2(FORE_LEN * jnp.sin(q2), UPPER_LEN + FORE_LEN * jnp.cos(q2))
    q3 = -(q1 + q2)  # hand axis vertical
    q4 = -q0  # cancel the yaw so the hand keeps the mocap's orientation
    return jnp.stack([q0, q1, q2, q3, q4])

