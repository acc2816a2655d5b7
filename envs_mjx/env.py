"""The Env contract of docs/architecture.md: pure `reset` / `step` / `render` over an MJX scene.

An `Env` is a Python object holding only static things (the MJX model, renderers, the
task spec); every method is a pure function of an `EnvState`, so `jax.jit(env.step)` and
`jax.vmap(env.step)` work directly.
"""

from __future__ import annotations

import contextlib
import io
import sys

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from flax import struct

# What `mujoco.mjx.warp` prints (to stdout) on import when the optional warp backend is not
# installed; we do not use that backend. Any other import failure of it still prints.
WARP_MISSING_LINES = ("Failed to import warp: No module named 'warp'",
                      "Failed to import mujoco_warp: No module named 'warp'")


def _import_mjx():
    """`mujoco.mjx` without the WARP_MISSING_LINES; everything else the import prints is
    passed on to stdout."""
    buf = io.StringIO()
    try:
        with contextlib.redirect_stdout(buf):
            from mujoco import mjx
    finally:
        for line in buf.getvalue().splitlines(keepends=True):
            if line.rstrip("\n") not in WARP_MISSING_LINES:
                sys.stdout.write(line)
    return mjx


mjx = _import_mjx()

from envs_mjx import scenes  # noqa: E402
from envs_mjx.arm import N_ARM_JOINTS, arm_ik  # noqa: E402
from envs_mjx.render import Camera, Renderer  # noqa: E402
from envs_mjx.tasks import PICKUP_AIR_GOAL_FRACTION, PICKUP_AIR_Z, PICKUP_CLEARANCE, TaskSpec  # noqa: E402

ACTION_SCALE = 0.02  # metres of mocap motion per unit action (multiworld)

LABEL_BACKGROUND, LABEL_ROBOT, LABEL_OBJECT = 0, 1, 2
_ROBOT_ROOTS = ("pedestal", "arm_base")
_OBJECT_ROOTS = ("puck", "door", "obj")


@struct.dataclass
class EnvState:
    """Physics state plus the step count inside the current episode."""

    data: mjx.Data
    t: jax.Array  # int32, steps since the episode started


def _subtree_bodies(m: mujoco.MjModel, root: int) -> set[int]:
    out = {root}
    for b in range(m.nbody):
        p = b
        while p > 0:
            if p == root:
                out.add(b)
                break
            p = m.body_parentid[p]
    return out


def geom_labels(m: mujoco.MjModel) -> np.ndarray:
    """int32[ngeom]: 1 for arm/pedestal geoms, 2 for the manipulated object, else 0."""
    labels = np.zeros(m.ngeom, np.int32)
    for roots, value in ((_ROBOT_ROOTS, LABEL_ROBOT), (_OBJECT_ROOTS, LABEL_OBJECT)):
        for name in roots:
            bid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, name)
            if bid < 0:
                continue
            bodies = _subtree_bodies(m, bid)
            labels[np.isin(m.geom_bodyid, list(bodies))] = value
    return labels


def finger_target(grip):
    """Finger opening target for the gripper action: -1 fully open, +1 closed (target 0;
    the cube stops the fingers first and the position servo then squeezes it)."""
    return scenes.FINGER_OPEN * 0.5 * (1.0 - grip)


def _uniform(key, low, high):
    low = jnp.asarray(low, jnp.float32)
    high = jnp.asarray(high, jnp.float32)
    return low + (high - low) * jax.random.uniform(key, low.shape)


class Env:
    """One Sawyer task. Build with `envs_mjx.make(name)`."""

    def __init__(self, spec: TaskSpec, with_object: bool = True):
        self.spec = spec
        self.name = spec.name
        self.with_object = with_object
        self.action_size = spec.action_size
        self.horizon = spec.horizon
        self.reset_free = spec.reset_free
        self.camera: Camera = spec.camera
        self.xml = scenes.scene_xml(spec.name, with_object)
        self.mj_model = mujoco.MjModel.from_xml_string(self.xml)
        # this process's first device: MJX's default, jax.devices()[0], belongs to process 0
        # when several processes run one program (jax.distributed)
        device = jax.local_devices()[0]
        self.mjx_model = mjx.put_model(self.mj_model, device=device)
        self.geom_label = geom_labels(self.mj_model)
        self._data0 = mjx.make_data(self.mjx_model, device=device)
        self._hand_body = self.mj_model.body("hand").id
        self._hand_low = jnp.asarray(spec.hand_low, jnp.float32)
        self._hand_high = jnp.asarray(spec.hand_high, jnp.float32)
        self.object_qadr = self._object_qpos_address()
        self._renderers: dict[tuple[int, int], Renderer] = {}
        self._empty: Env | None = None
        self._fingers = spec.kind == "pickup"
        if self._fingers:
            self._finger_qadr = np.array(
                [self.mj_model.joint(n).qposadr[0] for n in ("finger_l", "finger_r")])

    # ------------------------------------------------------------------ helpers
    def _object_qpos_address(self) -> int | None:
        if not self.with_object:
            return None
        joint = {"push": "puck_x", "door": "door_hinge", "pickup": "obj_free"}[self.spec.kind]
        return int(self.mj_model.joint(joint).qposadr[0])

    def renderer(self, width: int = 48, height: int = 48) -> Renderer:
        """The JAX renderer for this scene at a resolution (built once, then cached)."""
        for name, v in (("width", width), ("height", height)):
            if not isinstance(v, (int, np.integer)) or v <= 0:
                raise ValueError(f"render {name} must be a positive int, got {v!r}")
        key = (int(width), int(height))
        if key not in self._renderers:
            # Its constant buffers are computed once, eagerly, even when first asked for
            # inside a jit trace.
            with jax.ensure_compile_time_eval():
                self._renderers[key] = Renderer(self.mj_model, self.camera, self.geom_label, *key)
        return self._renderers[key]

    def check_action(self, action) -> None:
        """Raise ValueError for a wrong shape/dtype (static) or a non-finite value (concrete)."""
        shape = tuple(jnp.shape(action))
        if shape != (self.action_size,):
            raise ValueError(
                f"action for task {self.name!r} must have shape ({self.action_size},), got {shape}")
        dtype = jnp.result_type(action)
        if not jnp.issubdtype(dtype, jnp.floating):
            raise ValueError(
                f"action for task {self.name!r} must be a float array, got dtype {dtype}")
        try:
            values = np.asarray(action)
        except (jax.errors.TracerArrayConversionError, jax.errors.ConcretizationTypeError):
            return  # traced: the value is checked by the caller, the shape above
        if not np.all(np.isfinite(values)):
            raise ValueError(f"action for task {self.name!r} is not finite: {values}")

    def _action_to_mocap_delta(self, a):
        axes = self.mocap_axes
        return jnp.zeros(3, a.dtype).at[np.asarray(axes)].set(ACTION_SCALE * a[:len(axes)])

    @property
    def mocap_axes(self) -> tuple[int, ...]:
        """World axes moved by the first action components (the rest drive the gripper)."""
        return {"push": (0, 1), "door": (0, 1, 2), "pickup": (1, 2)}[self.spec.kind]

    def _build(self, hand_pos, obj_q, finger_q=None):
        """Data with the arm at IK(hand_pos), the object at obj_q, at rest. Only kinematics
        is computed (poses for rendering, hand and object readouts): `mjx.step` runs the full
        forward pass itself, and skipping it here keeps reset cheap to compile."""
        d = self._data0
        qpos = d.qpos.at[:N_ARM_JOINTS].set(arm_ik(hand_pos))
        if obj_q is not None:
            qpos = qpos.at[self.object_qadr:self.object_qadr + obj_q.shape[0]].set(obj_q)
        ctrl = d.ctrl
        if self._fingers:
            f = scenes.FINGER_OPEN if finger_q is None else finger_q
            qpos = qpos.at[self._finger_qadr].set(f)
            ctrl = jnp.full_like(ctrl, f)
        d = d.replace(qpos=qpos, ctrl=ctrl, mocap_pos=jnp.asarray(hand_pos, jnp.float32)[None])
        return mjx.kinematics(self.mjx_model, d)

    def place(self, hand_pos, object_pos=None, finger_gap=None) -> EnvState:
        """A state at rest with the hand at `hand_pos` (3,) and the object at `object_pos`
        (puck xy / door angle / object xyz); for goals, datasets, analyses and tests."""
        obj_q = None
        if self.with_object:
            if object_pos is None:
                raise ValueError(f"task {self.name!r} needs object_pos to place its object")
            obj_q = self._object_qpos(jnp.asarray(object_pos, jnp.float32))
        data = self._build(jnp.asarray(hand_pos, jnp.float32), obj_q, finger_gap)
        return EnvState(data=data, t=jnp.zeros((), jnp.int32))

    def _object_qpos(self, obj):
        """Object coordinates -> the object's qpos block."""
        kind = self.spec.kind
        if kind in ("door", "push"):  # hinge angle / the two slide joints
            return obj
        return jnp.concatenate([obj, jnp.array([1.0, 0.0, 0.0, 0.0])])  # free joint

    # ------------------------------------------------------------------ contract
    def reset(self, key) -> EnvState:
        """Hand at its reset position; object reset uniformly in its reset box."""
        obj = None
        if self.with_object:
            obj = self._object_qpos(
                _uniform(key, self.spec.object_reset_low, self.spec.object_reset_high))
        data = self._build(jnp.asarray(self.spec.hand_reset, jnp.float32), obj)
        return EnvState(data=data, t=jnp.zeros((), jnp.int32))

    def reset_episode(self, state: EnvState, key) -> EnvState:
        """Start a new episode: a full reset, or only t = 0 for reset-free tasks (door)."""
        if self.reset_free:
            return state.replace(t=jnp.zeros((), jnp.int32))
        return self.reset(key)

    def step(self, state: EnvState, action) -> EnvState:
        """Move the mocap target by 0.02 * clip(a, -1, 1) (clipped to the hand box), then
        simulate the task's n_substeps (0.1 s; the door 0.15 s)."""
        self.check_action(action)
        a = jnp.clip(jnp.asarray(action, jnp.float32), -1.0, 1.0)
        d = state.data
        mocap = jnp.clip(d.mocap_pos[0] + self._action_to_mocap_delta(a),
                         self._hand_low, self._hand_high)
        d = d.replace(mocap_pos=mocap[None])
        if self._fingers:
            d = d.replace(ctrl=jnp.full((2,), finger_target(a[2])))
        d = jax.lax.fori_loop(0, self.spec.n_substeps, lambda _, x: mjx.step(self.mjx_model, x), d)
        # Positions after the last substep (mjx.step leaves xpos one substep stale), so that
        # render, labels and object_state agree.
        d = mjx.kinematics(self.mjx_model, d)
        return EnvState(data=d, t=state.t + 1)

    def render(self, state: EnvState, width: int = 48, height: int = 48):
        """uint8[height, width, 3] camera image."""
        return self.renderer(width, height).render(state.data.geom_xpos, state.data.geom_xmat)[0]

    def render_labels(self, state: EnvState, width: int = 48, height: int = 48):
        """int32[height, width]: 0 background, 1 robot, 2 object (ground truth, for tests/eval)."""
        return self.renderer(width, height).render(state.data.geom_xpos, state.data.geom_xmat)[1]

    def render_both(self, state: EnvState, width: int = 48, height: int = 48):
        """(rgb, labels) from one ray cast."""
        return self.renderer(width, height).render(state.data.geom_xpos, state.data.geom_xmat)

    def hand_pos(self, state: EnvState):
        return state.data.xpos[self._hand_body]

    @property
    def object_size(self) -> int:
        """Length of `object_state`: puck xy, door angle, object xyz."""
        return {"push": 2, "door": 1, "pickup": 3}[self.spec.kind]

    def object_state(self, state: EnvState):
        """float32[k]: puck xy (push), door angle (door), object xyz (pickup)."""
        if not self.with_object:
            raise ValueError(f"empty scene of task {self.name!r} has no object state")
        a = self.object_qadr
        return state.data.qpos[a:a + self.object_size]

    def goal_distance(self, state: EnvState, goal: EnvState):
        """The paper's metric: |angle - goal| (door) or the object's position error (m)."""
        return self.object_distance(self.object_state(state), self.object_state(goal))

    def object_distance(self, obj, goal_obj):
        """`goal_distance` of object states [..., k] (`object_state`'s) -> [...]."""
        diff = obj - goal_obj
        if self.spec.kind == "door":
            return jnp.abs(diff[..., 0])
        return jnp.linalg.norm(diff, axis=-1)

    @property
    def kind(self) -> str:
        """"push" (puck, hurdles), "door" or "pickup": what the object state means."""
        return self.spec.kind

    @property
    def hand_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(low, high) of the hand's box (3,): where `step` keeps the mocap target."""
        return np.asarray(self.spec.hand_low, np.float32), np.asarray(self.spec.hand_high, np.float32)

    def random_hand(self, key):
        """A hand position uniform in the task's hand box (3,)."""
        return _uniform(key, self.spec.hand_low, self.spec.hand_high)

    def random_object_position(self, key):
        """An object position where the object can be (`TaskSpec.region`): one of the region's
        boxes with equal probability, then uniform in it (the hurdles' corridor sampler)."""
        boxes = self.spec.region
        k_box, k_pos = jax.random.split(key)
        low = jnp.asarray([b[0] for b in boxes], jnp.float32)
        high = jnp.asarray([b[1] for b in boxes], jnp.float32)
        i = jax.random.randint(k_box, (), 0, len(boxes))
        return _uniform(k_pos, low[i], high[i])

    def random_placement(self, k_hand, k_object) -> EnvState:
        """A state at rest (`place`) with the hand uniform in its box and the object where it
        can be (`random_object_position`): datasets and analyses that need every
        configuration, not goals."""
        return self.place(self.random_hand(k_hand), self.random_object_position(k_object))

    def region_placement(self, k_hand, k_object) -> EnvState:
        """The hurdles' scene-VAE pretraining states (the reference's corridor sampler): the
        object and the hand each placed independently over the object's region."""
        hand = self.random_object_position(k_hand)
        z = jnp.asarray(self.spec.hand_low[2:], jnp.float32)
        return self.place(jnp.concatenate([hand, z]), self.random_object_position(k_object))

    def away_placement(self, k_object) -> EnvState:
        """The object where it can be and the arm out of the camera's view (`hand_away`): the
        reference's object-VAE / LSTM pretraining images on the hurdles."""
        if self.spec.hand_away is None:
            raise ValueError(f"task {self.name!r} has no hand_away position")
        return self.place(jnp.asarray(self.spec.hand_away, jnp.float32),
                          self.random_object_position(k_object))

    def sample_goal(self, key) -> EnvState:
        """A state placed at a goal configuration drawn from the task's goal space."""
        k_obj, k_hand, k_air = jax.random.split(key, 3)
        s = self.spec
        obj = _uniform(k_obj, s.object_goal_low, s.object_goal_high)
        finger_q = None
        if s.kind == "push":
            hand = self._push_goal_hand(k_hand, obj)
        elif s.kind == "door":
            hand = self._door_goal_hand(obj[0])
        else:
            in_air = jax.random.uniform(k_air) < PICKUP_AIR_GOAL_FRACTION
            on_table = obj.at[2].set(scenes.CUBE_HALF)
            air = obj.at[2].set(jnp.maximum(obj[2], PICKUP_AIR_Z))
            obj = jnp.where(in_air, air, on_table)
            held = jnp.clip(obj + jnp.array([0.0, 0.0, scenes.GRASP_DROP]), self._hand_low,
                            self._hand_high)
            hand = jnp.where(in_air, held, self._pickup_away_hand(k_hand, obj))
            finger_q = jnp.where(in_air, scenes.CUBE_HALF, scenes.FINGER_OPEN).astype(jnp.float32)
        obj_q = self._object_qpos(obj) if self.with_object else None
        return EnvState(data=self._build(hand, obj_q, finger_q), t=jnp.zeros((), jnp.int32))

    def _clear_goal_hand(self, key, clear):
        """The first of 16 hand positions uniform in the hand goal box for which `clear`
        (positions [16, k] -> bool [16]) holds (the first draw if none does)."""
        s = self.spec
        hand = jax.vmap(lambda k: _uniform(k, s.hand_goal_low, s.hand_goal_high))(
            jax.random.split(key, 16))
        return hand[jnp.argmax(clear(hand))]

    def _push_goal_hand(self, key, puck):
        """Hand uniform in the hand goal box, not touching the puck."""
        xy = self._clear_goal_hand(
            key, lambda xy: jnp.linalg.norm(xy - puck, axis=-1) > scenes.PUCK_RADIUS + 0.02)
        return jnp.concatenate([xy, jnp.array([scenes.HAND_Z_PUSH])])

    def _pickup_away_hand(self, key, cube):
        """A table goal's hand (the reference's `generate_uncorrected_env_goals`: the cube on
        the table, the hand uniform in its goal box), its grasp point at least
        PICKUP_CLEARANCE from the cube's centre; the caller opens the fingers."""
        drop = jnp.array([0.0, 0.0, scenes.GRASP_DROP])
        return self._clear_goal_hand(
            key, lambda hand: jnp.linalg.norm(hand - drop - cube, axis=-1) >= PICKUP_CLEARANCE)

    def _door_goal_hand(self, angle):
        """Hook in the handle's gap for that door angle (how the door is held open)."""
        r = scenes.DOOR_HANDLE_R
        c, s_ = jnp.cos(angle), jnp.sin(angle)
        # Hook point in the door frame, rotated by the hinge angle.
        gx, gy = -r, scenes.DOOR_HOOK_Y
        x = scenes.DOOR_HINGE_X + c * gx - s_ * gy
        y = scenes.DOOR_Y + s_ * gx + c * gy
        hand = jnp.stack([x, y, jnp.asarray(0.15)])
        return jnp.clip(hand, self._hand_low, self._hand_high)

    def empty_scene(self) -> "Env":
        """The same task without the manipulated object (background-model data); built once."""
        if self._empty is None:
            self._empty = Env(self.spec, with_object=False)
        return self._empty
