"""MJCF builders for the five tabletop scenes (numbers from multiworld / the paper's appendix).

Collision is declared only through explicit `<contact><pair>` elements (every geom has
contype = conaffinity = 0). That keeps the pure-JAX MJX collision set small (it has no
broadphase: every candidate pair costs on every substep) and avoids the pairs MJX lacks
(box-cylinder): the puck is a cylinder against the table plane and the hand capsule, and
an invisible sphere proxy of the same radius (group 3, alpha 0) against the hurdle walls.
See docs/scenes.md for the full list of modelling choices.
"""

from __future__ import annotations

import math

from envs_mjx.arm import ROBOT_DARK, ROBOT_GREY, WELD_XML, arm_xml

# One env step = 0.1 s (multiworld: 2 ms x 50; the door 3 ms x 50 = 0.15 s, TaskSpec.n_substeps).
# We use 10 ms substeps: the weld and contacts use solref 0.02 (>= 2 timesteps, MuJoCo's
# stability floor), and the C-MuJoCo parity test/benchmark checks the outcome on the same model.
TIMESTEP = 0.01
N_SUBSTEPS = 10

TABLE_RGBA = "0.72 0.62 0.48 1"
PUCK_RGBA = "0.10 0.35 0.85 1"
WALL_RGBA = "0.35 0.55 0.35 1"
DOOR_RGBA = "0.20 0.45 0.80 1"
FRAME_RGBA = "0.45 0.40 0.35 1"
OBJ_RGBA = "0.95 0.75 0.10 1"

PUCK_RADIUS = 0.04
PUCK_HALF_HEIGHT = 0.015
PUCK_MASS = 0.1
PUCK_FRICTION = 0.5  # table-puck Coulomb coefficient
HAND_Z_PUSH = 0.06

# Hurdle walls (multiworld boxes): centre xy, half-size xy; half-height 0.04.
WALL_HALF_HEIGHT = 0.04
OUTER_WALLS = (
    ((-0.12, 0.62), (0.05, 0.19)),
    ((0.03, 0.76), (0.12, 0.05)),
    ((0.04, 0.44), (0.21, 0.05)),
    ((0.2, 0.62), (0.05, 0.19)),
)
MIDDLE_WALL = {
    "hurdle_bottom": ((0.04, 0.68), (0.01, 0.08)),
    "hurdle_top": ((0.05, 0.55), (0.01, 0.07)),
}


def hurdle_path(task: str) -> tuple[tuple[float, float], ...]:
    """Puck-centre waypoints (world xy) of the way around a hurdle task's middle wall: up (or
    down) the corridor left of it, across the gap beyond its end, back along the corridor on
    its right; each corridor and the gap at its centre line, the ends at the wall's centre
    height kept a puck radius inside the free region. The path the arm pushes the puck along
    (and occludes it on) in the occlusion analysis."""
    if task not in MIDDLE_WALL:
        raise ValueError(f"{task!r} has no hurdle; expected one of {sorted(MIDDLE_WALL)}")
    (wx, wy), (whx, why) = MIDDLE_WALL[task]
    x_lo = OUTER_WALLS[0][0][0] + OUTER_WALLS[0][1][0]  # inner faces of the outer walls
    x_hi = OUTER_WALLS[3][0][0] - OUTER_WALLS[3][1][0]
    y_lo = OUTER_WALLS[2][0][1] + OUTER_WALLS[2][1][1]
    y_hi = OUTER_WALLS[1][0][1] - OUTER_WALLS[1][1][1]
    left, right = (x_lo + wx - whx) / 2, (wx + whx + x_hi) / 2
    open_top = (wy - why) - y_lo < y_hi - (wy + why)  # the gap is beyond the wall's top end
    gap = (wy + why + y_hi) / 2 if open_top else (y_lo + wy - why) / 2
    end = min(max(wy, y_lo + PUCK_RADIUS), y_hi - PUCK_RADIUS)
    return ((left, end), (left, gap), (right, gap), (right, end))


# Door: vertical hinge at (DOOR_HINGE_X, DOOR_Y); the handle bar is DOOR_HANDLE_R from the
# hinge along -x and opens towards the robot (-y) for positive angles.
DOOR_HINGE_X = 0.14
DOOR_Y = 0.69
DOOR_HANDLE_R = 0.2
DOOR_BAR_Y = -0.07  # handle bar centre, door frame; the hook works in the gap behind it
DOOR_HOOK_Y = -0.055  # hand y (door frame) when the hook stem rests on the bar's back face
DOOR_MAX_ANGLE = 1.0472
# The reference's door (sawyer_door_pull_hook.xml): hinge damping 0.1, no friction loss, no
# armature, and a 0.4 x 0.4 x 0.02 m panel with its frame and handle at default density:
# 4.0 kg, 0.244 kg m^2 about the hinge, so a released door coasts (time constant 2.4 s).
# Our panel is smaller (it must stay inside the hand box's reach), so its inertia is given.
DOOR_MASS = 4.0
DOOR_HINGE_INERTIA = 0.244
DOOR_DAMPING = 0.1

# Pickup: cube half-size, visual sphere radius, grasp point below the hand frame.
CUBE_HALF = 0.02
OBJ_SPHERE_RADIUS = 0.035
GRASP_DROP = 0.05
FINGER_OPEN = 0.045

_NOCOL = 'contype="0" conaffinity="0"'


def _header(name: str) -> str:
    return f"""<mujoco model="{name}">
  <compiler angle="degree" autolimits="true"/>
  <option timestep="{TIMESTEP}" iterations="20" ls_iterations="10" integrator="Euler" cone="pyramidal"/>
  <visual><global fovy="45" offwidth="256" offheight="256"/><quality shadowsize="0"/></visual>
  <worldbody>
    <light name="top" pos="0 0.6 1.5" dir="0 0 -1" directional="true"/>
    <geom name="table" type="plane" pos="0 0.7 0" size="0.4 0.5 0.01" rgba="{TABLE_RGBA}" {_NOCOL}/>
"""


def _claw_geoms() -> str:
    """Pushing claw: visual palm + fingers, and a collision capsule reaching near the table."""
    return f"""
              <geom name="palm" type="box" pos="0 0 0.012" size="0.032 0.014 0.012" rgba="{ROBOT_DARK}" {_NOCOL} group="1"/>
              <geom name="claw_l" type="box" pos="0.022 0 -0.018" size="0.006 0.010 0.022" rgba="{ROBOT_GREY}" {_NOCOL} group="1"/>
              <geom name="claw_r" type="box" pos="-0.022 0 -0.018" size="0.006 0.010 0.022" rgba="{ROBOT_GREY}" {_NOCOL} group="1"/>
              <geom name="hand_col" type="capsule" fromto="0 0 -0.04 0 0 -0.012" size="0.015" rgba="{ROBOT_DARK}" {_NOCOL} group="1"/>"""


def _hook_geoms() -> str:
    """Door hook: two boxes, a vertical stem and a foot pointing away from the robot (+y)."""
    return f"""
              <geom name="palm" type="box" pos="0 0 0.012" size="0.03 0.014 0.012" rgba="{ROBOT_DARK}" {_NOCOL} group="1"/>
              <geom name="hook_stem" type="box" pos="0 0 -0.04" size="0.007 0.007 0.04" rgba="{ROBOT_GREY}" {_NOCOL} group="1"/>
              <geom name="hook_foot" type="box" pos="0 0.012 -0.075" size="0.007 0.012 0.005" rgba="{ROBOT_GREY}" {_NOCOL} group="1"/>"""


def _gripper_geoms() -> tuple[str, str]:
    """Two-finger gripper: fingers on slide joints along x, closing on the grasp point."""
    geoms = f"""
              <geom name="palm" type="box" pos="0 0 0.0" size="0.04 0.015 0.012" rgba="{ROBOT_DARK}" {_NOCOL} group="1"/>"""
    finger = 'type="slide" range="0 {o}" damping="2" armature="0.01"'.format(o=FINGER_OPEN)
    bodies = f"""
              <body name="finger_l" pos="0.008 0 {-GRASP_DROP + 0.01}">
                <inertial pos="0 0 0" mass="0.02" diaginertia="1e-5 1e-5 1e-5"/>
                <joint name="finger_l" axis="1 0 0" {finger}/>
                <geom name="finger_l" type="box" size="0.008 0.014 0.035" rgba="{ROBOT_GREY}" {_NOCOL} group="1"/>
              </body>
              <body name="finger_r" pos="-0.008 0 {-GRASP_DROP + 0.01}">
                <inertial pos="0 0 0" mass="0.02" diaginertia="1e-5 1e-5 1e-5"/>
                <joint name="finger_r" axis="-1 0 0" {finger}/>
                <geom name="finger_r" type="box" size="0.008 0.014 0.035" rgba="{ROBOT_GREY}" {_NOCOL} group="1"/>
              </body>"""
    return geoms, bodies


def _pair(g1: str, g2: str, friction: float = 0.5, condim: int = 3) -> str:
    return (f'    <pair geom1="{g1}" geom2="{g2}" condim="{condim}" '
            f'friction="{friction} {friction} 0.005 0.0001 0.0001" solref="0.02 1"/>\n')


def _footer(pairs: str, actuators: str = "") -> str:
    return f"""  </worldbody>
  <equality>{WELD_XML}</equality>
  <contact>
{pairs}  </contact>
  <actuator>{actuators}</actuator>
</mujoco>
"""


def _puck_body(pos: tuple[float, float]) -> str:
    # Planar puck: two slide joints on the table top. Multiworld's puck is a free body with
    # a huge inertia, i.e. it never tips or spins and stays on the table; the slide joints
    # give that motion directly, and the table's Coulomb friction (mu * m * g) becomes joint
    # friction loss. No table contact means no hopping on impacts, and MJX matches C MuJoCo.
    slide = f'type="slide" damping="0.05" frictionloss="{PUCK_FRICTION * PUCK_MASS * 9.81:.4f}"'
    return f"""
    <body name="puck" pos="{pos[0]} {pos[1]} {PUCK_HALF_HEIGHT}">
      <joint name="puck_x" axis="1 0 0" {slide}/>
      <joint name="puck_y" axis="0 1 0" {slide}/>
      <inertial pos="0 0 0" mass="{PUCK_MASS}" diaginertia="1e-4 1e-4 1e-4"/>
      <geom name="puck" type="cylinder" size="{PUCK_RADIUS} {PUCK_HALF_HEIGHT}" rgba="{PUCK_RGBA}" {_NOCOL}/>
      <geom name="puck_proxy" type="sphere" size="{PUCK_RADIUS}" rgba="0 0 0 0" group="3" {_NOCOL}/>
    </body>"""


def push_xml(task: str, with_object: bool = True) -> str:
    """Puck pushing, optionally with the hurdle walls of `hurdle_bottom` / `hurdle_top`."""
    walls = list(OUTER_WALLS) + ([MIDDLE_WALL[task]] if task in MIDDLE_WALL else [])
    if task == "puck_push":
        walls = []
    xml = _header(task) + arm_xml(_claw_geoms())
    wall_names = []
    for i, ((cx, cy), (hx, hy)) in enumerate(walls):
        name = f"wall{i}"
        wall_names.append(name)
        xml += (f'    <geom name="{name}" type="box" pos="{cx} {cy} {WALL_HALF_HEIGHT}" '
                f'size="{hx} {hy} {WALL_HALF_HEIGHT}" rgba="{WALL_RGBA}" {_NOCOL}/>\n')
    pairs = ""
    if with_object:
        xml += _puck_body((0.0, 0.0))  # body at the origin: slide qpos = world xy
        pairs += _pair("hand_col", "puck", friction=0.1)
        for name in wall_names:
            pairs += _pair("puck_proxy", name, friction=0.1)
    return xml + _footer(pairs)


def door_xml(with_object: bool = True) -> str:
    """Door on a vertical hinge with a handle bar; the hand carries a hook."""
    xml = _header("door_open") + arm_xml(_hook_geoms())
    # Frame post at the hinge and a lintel: static, background.
    xml += (f'    <geom name="door_post" type="box" pos="{DOOR_HINGE_X + 0.02} {DOOR_Y} 0.14" '
            f'size="0.015 0.02 0.14" rgba="{FRAME_RGBA}" {_NOCOL}/>\n')
    xml += (f'    <geom name="door_wall" type="box" pos="{DOOR_HINGE_X + 0.1} {DOOR_Y + 0.03} 0.14" '
            f'size="0.07 0.01 0.14" rgba="{FRAME_RGBA}" {_NOCOL}/>\n')
    pairs = ""
    if with_object:
        r = DOOR_HANDLE_R
        izz = DOOR_HINGE_INERTIA - DOOR_MASS * 0.125 ** 2  # about the centre of mass
        xml += f"""
    <body name="door" pos="{DOOR_HINGE_X} {DOOR_Y} 0">
      <joint name="door_hinge" type="hinge" axis="0 0 1" range="0 {math.degrees(DOOR_MAX_ANGLE)}" damping="{DOOR_DAMPING}" armature="0"/>
      <inertial pos="-0.125 0 0.12" mass="{DOOR_MASS}" diaginertia="{izz} {izz} {izz}"/>
      <geom name="door_panel" type="box" pos="-0.125 0 0.12" size="0.125 0.01 0.12" rgba="{DOOR_RGBA}" {_NOCOL}/>
      <geom name="handle_bar" type="box" pos="{-r} {DOOR_BAR_Y} 0.10" size="0.06 0.008 0.01" rgba="{PUCK_RGBA}" {_NOCOL}/>
      <geom name="handle_post_a" type="box" pos="{-r + 0.055} {DOOR_BAR_Y / 2} 0.10" size="0.005 {-DOOR_BAR_Y / 2 - 0.01} 0.01" rgba="{PUCK_RGBA}" {_NOCOL}/>
      <geom name="handle_post_b" type="box" pos="{-r - 0.055} {DOOR_BAR_Y / 2} 0.10" size="0.005 {-DOOR_BAR_Y / 2 - 0.01} 0.01" rgba="{PUCK_RGBA}" {_NOCOL}/>
    </body>"""
        for hook in ("hook_stem", "hook_foot"):
            pairs += _pair(hook, "handle_bar", friction=0.2)
            pairs += _pair(hook, "door_panel", friction=0.2)
    return xml + _footer(pairs)


def pickup_xml(with_object: bool = True) -> str:
    """Cube (drawn as a larger intangible sphere) and a two-finger friction gripper."""
    geoms, bodies = _gripper_geoms()
    xml = _header("pickup") + arm_xml(geoms, bodies)
    pairs = ""
    if with_object:
        xml += f"""
    <body name="obj" pos="0 0.6 {CUBE_HALF}">
      <freejoint name="obj_free"/>
      <inertial pos="0 0 0" mass="0.05" diaginertia="2e-5 2e-5 2e-5"/>
      <geom name="obj_cube" type="box" size="{CUBE_HALF} {CUBE_HALF} {CUBE_HALF}" rgba="{OBJ_RGBA}" {_NOCOL}/>
      <geom name="obj_sphere" type="sphere" size="{OBJ_SPHERE_RADIUS}" rgba="{OBJ_RGBA}" {_NOCOL} group="1"/>
    </body>"""
        pairs += _pair("table", "obj_cube", friction=1.0)
        pairs += _pair("finger_l", "obj_cube", friction=1.5, condim=4)
        pairs += _pair("finger_r", "obj_cube", friction=1.5, condim=4)
    actuators = (f'\n    <position name="finger_l" joint="finger_l" kp="200" ctrlrange="0 {FINGER_OPEN}"/>'
                 f'\n    <position name="finger_r" joint="finger_r" kp="200" ctrlrange="0 {FINGER_OPEN}"/>\n  ')
    return xml + _footer(pairs, actuators)


def scene_xml(task: str, with_object: bool = True) -> str:
    if task in ("puck_push", "hurdle_bottom", "hurdle_top"):
        return push_xml(task, with_object)
    if task == "door_open":
        return door_xml(with_object)
    if task == "pickup":
        return pickup_xml(with_object)
    raise ValueError(f"unknown task {task!r}")
