"""Tests for the JAX ray-casting renderer (envs_mjx.render) on a tiny MJCF scene.

Agreement with MuJoCo's own OpenGL renderer is checked by bench/render_vs_mujoco.py (needs
OSMesa); here the camera model is checked against an independent pinhole model.
"""

import math

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from envs_mjx.render import AMBIENT, BACKGROUND_RGB, DIFFUSE, Camera, Renderer
from pinhole import pinhole

SCENE = """
<mujoco>
  <worldbody>
    <geom name="floor" type="plane" size="0 0 0.1" rgba="0.5 0.5 0.5 1"/>
    <geom name="wall" type="box" pos="0 0.3 0.1" size="0.3 0.02 0.1" rgba="0.2 0.2 0.8 1"/>
    <geom name="static_ghost" type="box" pos="0 0 0.1" size="0.5 0.5 0.1" rgba="0 0 0 0" group="3"/>
    <body name="ball" pos="0 0 0.1"><freejoint/>
      <geom name="ball" type="sphere" size="0.03" rgba="1 0 0 1"/>
      <geom name="proxy" type="sphere" size="0.08" rgba="0 0 0 0" group="3"/>
    </body>
    <body name="crate" pos="0.2 0 0.05"><freejoint/>
      <geom name="crate" type="box" size="0.05 0.05 0.05" rgba="1 1 1 1"/></body>
    <body name="pill" pos="-0.2 0 0.05"><freejoint/>
      <geom name="pill" type="capsule" size="0.02 0.04" rgba="0 1 0 1"/></body>
    <body name="can" pos="0 -0.2 0.05"><freejoint/>
      <geom name="can" type="cylinder" size="0.04 0.02" rgba="1 1 0 1"/></body>
    <body name="ghosts" pos="0 0.2 0.1"><freejoint/>
      <geom name="ghost_alpha0" type="sphere" size="0.05" rgba="1 0 1 0"/>
      <geom name="ghost_group4" type="sphere" pos="0.1 0 0" size="0.05" rgba="1 0 1 1" group="4"/>
    </body>
    <body name="marker" mocap="true" pos="0.3 0.3 0.2">
      <geom name="marker" type="sphere" size="0.02" rgba="0 1 1 1"/></body>
  </worldbody>
</mujoco>
"""

# looks along +y and down: world +x is image right, world +z is image up-ish
CAM = Camera(lookat=(0.0, 0.0, 0.05), distance=1.0, elevation=-60.0, azimuth=90.0)
FREE = ("ball", "crate", "pill", "can", "ghosts")


@pytest.fixture(scope="module")
def model():
    return mujoco.MjModel.from_xml_string(SCENE)


def gid(m, name):
    return m.geom(name).id


@pytest.fixture(scope="module")
def renderer(model):
    # label = geom id + 1 so labels identify geoms exactly
    return Renderer(model, CAM, np.arange(1, model.ngeom + 1), width=48, height=48)


@pytest.fixture(scope="module")
def render(renderer):
    return jax.jit(renderer.render)


def poses(m, where=None, mocap=None):
    """geom_xpos, geom_xmat (float32) after placing free bodies; unplaced ones go far away."""
    d = mujoco.MjData(m)
    for i, name in enumerate(FREE):
        adr = m.jnt_qposadr[m.body_jntadr[m.body(name).id]]
        d.qpos[adr:adr + 7] = [10.0 + i, 10.0, 0.0, 1, 0, 0, 0]  # far behind the camera's view
    for name, pos in (where or {}).items():
        adr = m.jnt_qposadr[m.body_jntadr[m.body(name).id]]
        d.qpos[adr:adr + 3] = pos
    if mocap is not None:
        d.mocap_pos[0] = mocap
    mujoco.mj_forward(m, d)
    return d.geom_xpos.astype(np.float32), d.geom_xmat.reshape(-1, 3, 3).astype(np.float32)


def pixel(cam, p, width=48, height=48):
    """Nearest pixel (row, col) to the projection of p; must be inside the image."""
    rc = np.round(pinhole(cam, p, width, height)).astype(int)
    assert 0 <= rc[0] < height and 0 <= rc[1] < width, (p, rc)
    return tuple(rc)


def centroid(labels, value):
    rc = np.argwhere(np.asarray(labels) == value)
    assert len(rc), f"label {value} not in the image"
    return rc.mean(0)


def test_shapes_and_dtypes(model):
    for w, h in ((48, 48), (128, 96)):
        r = Renderer(model, CAM, np.zeros(model.ngeom, np.int32), width=w, height=h)
        rgb, lab = jax.jit(r.render)(*poses(model, {"ball": (0, 0, 0.1)}))
        assert rgb.shape == (h, w, 3) and rgb.dtype == jnp.uint8
        assert lab.shape == (h, w) and lab.dtype == jnp.int32


def test_sphere_lands_on_pinhole_pixel(model):
    w, h = 128, 96
    r = jax.jit(Renderer(model, CAM, np.arange(1, model.ngeom + 1), width=w, height=h).render)
    ball = gid(model, "ball") + 1
    for p in [(0.0, 0.0, 0.1), (0.15, 0.1, 0.2), (-0.2, -0.15, 0.05)]:
        _, lab = r(*poses(model, {"ball": p}))
        row, col = pinhole(CAM, p, w, h)
        assert np.allclose(centroid(lab, ball), (row, col), atol=0.35), p
        assert int(lab[pixel(CAM, p, w, h)]) == ball


def test_motion_moves_label_centroid_as_predicted(model, render):
    ball = gid(model, "ball") + 1
    p0 = np.array([0.0, 0.0, 0.1])
    c0 = centroid(render(*poses(model, {"ball": p0}))[1], ball)
    for step in ([0.08, 0, 0], [0, 0, 0.08], [0, 0.1, 0]):
        p1 = p0 + np.array(step)
        c1 = centroid(render(*poses(model, {"ball": p1}))[1], ball)
        want = np.subtract(pinhole(CAM, p1, 48, 48), pinhole(CAM, p0, 48, 48))
        assert np.linalg.norm(want) > 2  # a real move of several pixels
        assert np.allclose(c1 - c0, want, atol=0.5), (step, c1 - c0, want)
    # +x is image right (column grows), +z is image up (row shrinks): not mirrored
    assert centroid(render(*poses(model, {"ball": p0 + [0.08, 0, 0]}))[1], ball)[1] > c0[1] + 2
    assert centroid(render(*poses(model, {"ball": p0 + [0, 0, 0.08]}))[1], ball)[0] < c0[0] - 2


def test_nearer_geom_occludes(model, render):
    ball, crate, wall = (gid(model, n) + 1 for n in ("ball", "crate", "wall"))
    el, az = math.radians(CAM.elevation), math.radians(CAM.azimuth)
    fwd = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
    target = np.array([0.0, 0.0, 0.1])
    rc = pixel(CAM, target)
    front, back = target - 0.15 * fwd, target + 0.15 * fwd  # on the same pixel's ray
    lab = render(*poses(model, {"ball": front, "crate": back}))[1]
    assert int(lab[rc[0], rc[1]]) == ball
    lab = render(*poses(model, {"ball": back, "crate": front}))[1]
    assert int(lab[rc[0], rc[1]]) == crate
    # moving geom against the pre-cast static wall: hidden behind it, visible in front of it
    behind = np.array([0.0, 0.37, 0.05])
    rc = pixel(CAM, behind)
    assert int(render(*poses(model, {"ball": behind}))[1][rc[0], rc[1]]) == wall
    ahead = np.array([0.0, 0.22, 0.1])
    rc = pixel(CAM, ahead)
    assert int(render(*poses(model, {"ball": ahead}))[1][rc[0], rc[1]]) == ball


def test_invisible_geoms_are_not_drawn(model, render):
    hidden = {gid(model, n) + 1 for n in ("static_ghost", "proxy", "ghost_alpha0", "ghost_group4")}
    lab = np.asarray(render(*poses(model, {"ball": (0, 0, 0.1), "ghosts": (0, 0.1, 0.1)}))[1])
    assert not hidden & set(np.unique(lab).tolist())
    # the ball inside its (hidden) proxy, and the floor under the hidden static box, show
    assert gid(model, "ball") + 1 in lab and gid(model, "floor") + 1 in lab


def test_degenerate_geom_is_ignored(model):
    m = mujoco.MjModel.from_xml_string(SCENE)
    m.geom_size[gid(m, "ball")] = 0.0
    lab = jax.jit(Renderer(m, CAM, np.arange(1, m.ngeom + 1)).render)(*poses(m, {"ball": (0, 0, 0.1)}))[1]
    assert gid(m, "ball") + 1 not in np.asarray(lab)


def test_labels_follow_geom_label(model):
    geom_label = np.zeros(model.ngeom, np.int32)
    geom_label[gid(model, "ball")] = 2
    geom_label[[gid(model, "crate"), gid(model, "marker")]] = 1
    r = jax.jit(Renderer(model, CAM, geom_label).render)
    lab = np.asarray(r(*poses(model, {"ball": (0, 0, 0.1), "crate": (0.2, 0, 0.05)}))[1])
    assert set(np.unique(lab).tolist()) == {0, 1, 2}
    ids = np.asarray(jax.jit(Renderer(model, CAM, np.arange(1, model.ngeom + 1)).render)(
        *poses(model, {"ball": (0, 0, 0.1), "crate": (0.2, 0, 0.05)}))[1]) - 1
    np.testing.assert_array_equal(lab, np.where(ids >= 0, geom_label[np.maximum(ids, 0)], 0))


def test_mocap_geom_moves(model, render):
    marker = gid(model, "marker") + 1
    for p in [(0.1, 0.1, 0.2), (-0.1, 0.2, 0.1)]:
        lab = render(*poses(model, mocap=p))[1]
        assert np.allclose(centroid(lab, marker), pinhole(CAM, p, 48, 48), atol=0.5)


def test_shading_lambert_and_background(model, render):
    crate = gid(model, "crate") + 1
    c = np.array([0.0, 0.0, 0.05])
    rgb, lab = render(*poses(model, {"crate": c}))
    rgb, lab = np.asarray(rgb), np.asarray(lab)
    el = math.radians(CAM.elevation)
    # light direction: normalize(-forward + z) with forward = (0, cos el, sin el) here
    light = np.array([0.0, -math.cos(el), 1 - math.sin(el)])
    light /= np.linalg.norm(light)
    for point, normal in (((0, 0, 0.1), (0, 0, 1)), ((0, -0.05, 0.05), (0, -1, 0))):
        r, col = pixel(CAM, np.asarray(point) + [0, -0.002, 0.002])
        assert lab[r, col] == crate
        want = round(255 * (AMBIENT + DIFFUSE * max(0.0, float(np.dot(normal, light)))))
        assert np.all(np.abs(rgb[r, col].astype(int) - want) <= 2), (normal, rgb[r, col], want)
    top = rgb[pixel(CAM, (0, 0, 0.1))].astype(int)
    side = rgb[pixel(CAM, (0, -0.052, 0.05))].astype(int)
    assert top.sum() > side.sum() + 100  # the face towards the light is clearly brighter
    # rays above the horizon hit nothing
    sky = Camera(lookat=(0.0, 0.0, 1.0), distance=1.0, elevation=30.0, azimuth=90.0)
    rgb, lab = jax.jit(Renderer(model, sky, np.ones(model.ngeom)).render)(*poses(model))
    assert np.all(np.asarray(lab) == 0) and np.all(np.asarray(rgb) == np.array(BACKGROUND_RGB))


def test_rays_parallel_to_faces_and_axes(model):
    # straight down through the exact centre pixel (odd size): rays parallel to box faces and to
    # the capsule / cylinder axes, 1/d and quadratic terms degenerate
    cam = Camera(lookat=(0.0, 0.0, 0.0), distance=1.0, elevation=-90.0, azimuth=0.0)
    r = jax.jit(Renderer(model, cam, np.arange(1, model.ngeom + 1), width=49, height=49).render)
    for name, z in (("crate", 0.05), ("pill", 0.06), ("can", 0.02), ("ball", 0.03)):
        rgb, lab = r(*poses(model, {name: (0.0, 0.0, z)}))
        assert int(lab[24, 24]) == gid(model, name) + 1, name
        # the top is lit at n.l = light_z = 1 for a camera looking straight down
        expect = np.round(model.geom_rgba[gid(model, name), :3] * 255 * (AMBIENT + DIFFUSE))
        assert np.all(np.abs(np.asarray(rgb[24, 24], int) - expect) <= 2), name


def test_jit_and_vmap_match_single_calls(model, renderer, render):
    rng = np.random.default_rng(0)
    batch = [poses(model, {"ball": rng.uniform(-0.2, 0.2, 3) + [0, 0, 0.2],
                           "crate": rng.uniform(-0.2, 0.2, 3) + [0, 0, 0.2],
                           "pill": rng.uniform(-0.2, 0.2, 3) + [0, 0, 0.2]}) for _ in range(4)]
    xpos = np.stack([b[0] for b in batch])
    xmat = np.stack([b[1] for b in batch])
    rgb_b, lab_b = jax.jit(jax.vmap(renderer.render))(xpos, xmat)
    for i in range(len(batch)):
        rgb, lab = render(xpos[i], xmat[i])
        np.testing.assert_array_equal(rgb_b[i], rgb)
        np.testing.assert_array_equal(lab_b[i], lab)
    assert len({np.asarray(lab_b[i]).tobytes() for i in range(4)}) == 4  # poses really differ
