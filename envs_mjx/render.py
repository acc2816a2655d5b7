"""Pure-JAX camera renderer: analytic ray casting against MuJoCo primitive geoms.

No OpenGL. One ray per pixel through the pixel centre of a MuJoCo *free* camera; the nearest
hit among plane / sphere / capsule / ellipsoid / cylinder / box geoms decides the pixel's colour
(Lambert + ambient) and label. Geometry matches `mujoco.Renderer` with an `MjvCamera` of type
FREE (same basis, vertical fovy, horizontal extent from the aspect ratio, near/far clipping at
`vis.map.znear/zfar * stat.extent`, planes drawn from both sides like MuJoCo's segmentation).

Speed: geoms welded to the world never move, so they are cast once in `__init__` into constant
per-pixel depth / colour / label buffers; per frame only the moving geoms are cast and merged by
depth. Rays are parametrised as d = forward + u*right + v*up, so the ray parameter t *is* the
eye-space depth (what OpenGL clips and z-tests on) and each geom's local-frame ray direction is
an affine function of (u, v): per frame only a few scalars per geom are computed with small
matrix products, and per pixel everything is elementwise on separate x/y/z arrays, batched per
geom type. The nearest hit, its geom and its shading come out of one float min-reduction over
packed keys (see `_pack`): XLA's argmin and per-pixel gathers are slow on CPU.

Lighting: one directional light shining from behind the camera and from above (direction
towards the light = normalize(-forward + world_up)), intensity = AMBIENT + DIFFUSE * max(0, n.l).
Transparency (0 < alpha < 1) is ignored: visible geoms are drawn opaque. Sites, meshes, height
fields, the skybox and MuJoCo's own lights/materials beyond rgba are not rendered.
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

AMBIENT = 0.35
DIFFUSE = 0.65
BACKGROUND_RGB = (40, 40, 40)  # dark grey for rays that hit nothing
_VISIBLE_GROUPS = 3  # mjvOption.geomgroup default: groups 0, 1, 2 on, 3..5 off
_TINY = 1e-12  # guards divisions by ray components that are (almost) zero
_MISS = 1e30  # depth of a miss: finite, so that bits can be packed into it (see _pack)
_COS_BITS = 7  # n.l quantised to 1/127: <= 0.7 grey levels of error in the uint8 output

_PLANE = int(mujoco.mjtGeom.mjGEOM_PLANE)
_SPHERE = int(mujoco.mjtGeom.mjGEOM_SPHERE)
_CAPSULE = int(mujoco.mjtGeom.mjGEOM_CAPSULE)
_ELLIPSOID = int(mujoco.mjtGeom.mjGEOM_ELLIPSOID)
_CYLINDER = int(mujoco.mjtGeom.mjGEOM_CYLINDER)
_BOX = int(mujoco.mjtGeom.mjGEOM_BOX)
_TYPES = (_PLANE, _SPHERE, _CAPSULE, _ELLIPSOID, _CYLINDER, _BOX)


@dataclasses.dataclass(frozen=True)
class Camera:
    """A MuJoCo free camera (mjvCamera type FREE); angles in degrees."""

    lookat: tuple[float, float, float]
    distance: float
    elevation: float
    azimuth: float
    fovy: float = 45.0  # vertical field of view (= mj_model.vis.global_.fovy)


def camera_frame(camera: Camera) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(position, forward, right, up) in world coordinates, as mjv_updateCamera computes them."""
    az, el = math.radians(camera.azimuth), math.radians(camera.elevation)
    ca, sa, ce, se = math.cos(az), math.sin(az), math.cos(el), math.sin(el)
    forward = np.array([ce * ca, ce * sa, se])
    up = np.array([-se * ca, -se * sa, ce])
    right = np.cross(forward, up)
    pos = np.asarray(camera.lookat, np.float64) - camera.distance * forward
    return pos, forward, right, up


def _safe(d):
    """d with |d| >= _TINY (sign kept) so 1/d and 0*(1/d) stay finite."""
    return jnp.where(d >= 0, jnp.maximum(d, _TINY), jnp.minimum(d, -_TINY))


def _sign(x):
    """sign with sign(0) = +1 (a side must always be chosen)."""
    return jnp.where(x >= 0, 1.0, -1.0)


# Intersection routines, in the geom's local frame: o = ray origin (per geom, [G,1,1] each),
# d = ray direction ([G,h,w] each), s = size and si = 1/size (constants: multiplying is much
# cheaper than dividing per pixel), l = direction towards the light (per geom), ia = 1/|d|^2 per
# pixel (rotation invariant). Each returns (t, cos): the entry depth (inf on a
# miss) and n.l for the unit outward normal n at the entry point.


def _hit_sphere(o, d, s, si, l, ia):
    ox, oy, oz = o
    dx, dy, dz = d
    r = s[0]
    # t = (-b - sqrt(b^2 - a c)) / a, written with 1/a only
    b = (ox * dx + oy * dy + oz * dz) * ia
    c = ox * ox + oy * oy + oz * oz - r * r
    disc = b * b - c * ia
    t = jnp.where(disc >= 0, -b - jnp.sqrt(jnp.maximum(disc, 0.0)), jnp.inf)
    cos = ((ox + t * dx) * l[0] + (oy + t * dy) * l[1] + (oz + t * dz) * l[2]) * si[0]
    return t, cos


def _hit_ellipsoid(o, d, s, si, l, ia):
    del ia
    o = [o[k] * si[k] for k in range(3)]  # scaled to the unit sphere
    d = [d[k] * si[k] for k in range(3)]
    aa = d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
    b = o[0] * d[0] + o[1] * d[1] + o[2] * d[2]
    c = o[0] * o[0] + o[1] * o[1] + o[2] * o[2] - 1.0
    disc = b * b - aa * c
    t = jnp.where(disc >= 0, (-b - jnp.sqrt(jnp.maximum(disc, 0.0))) / aa, jnp.inf)
    n = [(o[k] + t * d[k]) * si[k] for k in range(3)]  # gradient of |p/s|^2 ~ p/s^2
    dot = n[0] * l[0] + n[1] * l[1] + n[2] * l[2]
    return t, dot * jax.lax.rsqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2] + _TINY)


def _infinite_cylinder(o, d, r):
    """Entry of the ray into the infinite cylinder x^2+y^2 <= r^2: (t, z at t, valid)."""
    ox, oy, oz = o
    dx, dy, dz = d
    a2 = dx * dx + dy * dy
    b2 = ox * dx + oy * dy
    c2 = ox * ox + oy * oy - r * r
    disc2 = b2 * b2 - a2 * c2
    ok = (disc2 >= 0) & (a2 > _TINY)
    tc = (-b2 - jnp.sqrt(jnp.maximum(disc2, 0.0))) / jnp.maximum(a2, _TINY)
    return tc, oz + tc * dz, ok


def _hit_capsule(o, d, s, si, l, ia):
    ox, oy, oz = o
    dx, dy, dz = d
    r, h = s[0], s[1]
    tc, zc, ok = _infinite_cylinder(o, d, r)
    body = ok & (jnp.abs(zc) <= h)
    # Otherwise the first hit can only be on the cap sphere at the end where the ray entered the
    # infinite cylinder (or, for rays along the axis, the end facing the ray).
    ocz = oz - jnp.where(ok, _sign(zc), -_sign(dz)) * h
    b = (ox * dx + oy * dy + ocz * dz) * ia
    c = ox * ox + oy * oy + ocz * ocz - r * r
    disc = b * b - c * ia
    ts = -b - jnp.sqrt(jnp.maximum(disc, 0.0))
    t = jnp.where(body, tc, jnp.where(disc >= 0, ts, jnp.inf))
    nz = jnp.where(body, 0.0, ocz + t * dz)
    cos = ((ox + t * dx) * l[0] + (oy + t * dy) * l[1] + nz * l[2]) * si[0]
    return t, cos


def _hit_cylinder(o, d, s, si, l, ia):
    del ia
    ox, oy, oz = o
    dx, dy, dz = d
    r, h = s[0], s[1]
    tc, zc, ok = _infinite_cylinder(o, d, r)
    t_side = jnp.where(ok & (jnp.abs(zc) <= h) & (tc > 0), tc, jnp.inf)
    # Flat cap on the side of the origin; only reachable from outside the slab |z| <= h.
    so = _sign(oz)
    tcap = (so * h - oz) / _safe(dz)
    px, py = ox + tcap * dx, oy + tcap * dy
    cap_ok = (jnp.abs(oz) > h) & (tcap > 0) & (px * px + py * py <= r * r)
    t_cap = jnp.where(cap_ok, tcap, jnp.inf)
    t = jnp.minimum(t_side, t_cap)
    cos_side = ((ox + t * dx) * l[0] + (oy + t * dy) * l[1]) * si[0]
    return t, jnp.where(t_side <= t_cap, cos_side, so * l[2])


def _hit_box(o, d, s, si, l, ia):
    del si, ia
    near, far, face = [], [], []
    for k in range(3):  # slab test per axis
        inv = 1.0 / _safe(d[k])
        t1 = (-s[k] - o[k]) * inv
        t2 = (s[k] - o[k]) * inv
        near.append(jnp.minimum(t1, t2))
        far.append(jnp.maximum(t1, t2))
        face.append(-_sign(d[k]) * l[k])  # the entry face on axis k faces against the ray
    tn = jnp.maximum(jnp.maximum(near[0], near[1]), near[2])
    tf = jnp.minimum(jnp.minimum(far[0], far[1]), far[2])
    t = jnp.where(tn <= tf, tn, jnp.inf)
    cos = jnp.where(near[0] >= jnp.maximum(near[1], near[2]), face[0],
                    jnp.where(near[1] >= near[2], face[1], face[2]))
    return t, cos


def _hit_plane(o, d, s, si, l, ia):
    del si, ia
    ox, oy, oz = o
    dx, dy, dz = d
    t = -oz / _safe(dz)
    px, py = ox + t * dx, oy + t * dy
    finite = (s[0] > 0) & (s[1] > 0)
    inside = ~finite | ((jnp.abs(px) <= s[0]) & (jnp.abs(py) <= s[1]))
    # Both sides are drawn, as in MuJoCo's segmentation pass (its RGB pass shows the underside
    # of a plane dimmed); the normal is the side facing the camera.
    t = jnp.where((oz * dz < 0) & inside, t, jnp.inf)
    return t, jnp.broadcast_to(_sign(oz) * l[2], t.shape)


_HIT = {_PLANE: _hit_plane, _SPHERE: _hit_sphere, _CAPSULE: _hit_capsule,
        _ELLIPSOID: _hit_ellipsoid, _CYLINDER: _hit_cylinder, _BOX: _hit_box}


def _pack(t, cos, ids, nb):
    """Float keys whose minimum carries depth, shading and geom index together.

    For t > 0 the order of float32 values equals the order of their int32 bit patterns, so the
    low mantissa bits of t can hold (quantised n.l, index) and a plain (vectorised) float min
    picks the nearest geom. t loses nb + _COS_BITS low mantissa bits (rounded down: relative
    error < 2^(nb + _COS_BITS - 23), e.g. 0.1 mm at 0.4 m for 9-16 moving geoms). Needs t > 0
    (t > znear or _MISS here). Surfaces within that depth error of each other tie: the lower
    n.l, then the lower index wins, which only matters along intersection lines.
    """
    q = (jnp.clip(cos, 0.0, 1.0) * ((1 << _COS_BITS) - 1) + 0.5).astype(jnp.int32)
    low = nb + _COS_BITS
    bits = jax.lax.bitcast_convert_type(t, jnp.int32) & ~((1 << low) - 1)
    return jax.lax.bitcast_convert_type(bits | (q << nb) | ids, jnp.float32)


def _unpack(key, nb):
    """Inverse of `_pack` for the minimum key: (t, cos, index)."""
    bits = jax.lax.bitcast_convert_type(key, jnp.int32)
    k = bits & ((1 << nb) - 1)
    cos = ((bits >> nb) & ((1 << _COS_BITS) - 1)).astype(jnp.float32) / ((1 << _COS_BITS) - 1)
    t = jax.lax.bitcast_convert_type(bits & ~((1 << (nb + _COS_BITS)) - 1), jnp.float32)
    return t, cos, k


def _degenerate(gtype: int, size: np.ndarray) -> bool:
    if gtype == _PLANE:
        return False
    if gtype in (_SPHERE, _CAPSULE):
        return not size[0] > 0
    if gtype == _CYLINDER:
        return not (size[0] > 0 and size[1] > 0)
    return not np.all(size > 0)  # box, ellipsoid


class Renderer:
    """Ray-casting renderer for one fixed camera and model.

    `render(geom_xpos, geom_xmat)` -> (rgb uint8[h,w,3], labels int32[h,w]); pure, jit/vmap-able.
    Drawn geoms: primitive types with rgba alpha > 0 in groups 0-2 (MuJoCo's default visible
    groups). Geoms whose body is welded to the world (body_weldid == 0; MuJoCo gives mocap
    bodies their own weld id) are pre-cast once at the poses of mj_forward on `mj_model`; their
    entries in `render`'s inputs are ignored, so the model's static geoms must not change later.
    """

    def __init__(self, mj_model: mujoco.MjModel, camera: Camera, geom_label: np.ndarray,
                 width: int = 48, height: int = 48):
        self.camera, self.width, self.height = camera, int(width), int(height)
        m = mj_model
        geom_label = np.asarray(geom_label, np.int32).reshape(-1)
        if geom_label.shape != (m.ngeom,):
            raise ValueError(f"geom_label has shape {geom_label.shape}, expected ({m.ngeom},)")

        # Effective colour as MuJoCo picks it: the material's rgba when the geom has a material
        # and kept the default geom rgba, else the geom's rgba.
        rgba = np.array(m.geom_rgba, np.float64)
        default = np.all(np.isclose(rgba, [0.5, 0.5, 0.5, 1.0]), axis=1)
        use_mat = (m.geom_matid >= 0) & default
        rgba[use_mat] = m.mat_rgba[m.geom_matid[use_mat]]
        size = np.array(m.geom_size, np.float64)
        drawn = np.array([
            int(m.geom_type[g]) in _TYPES and rgba[g, 3] > 0 and m.geom_group[g] < _VISIBLE_GROUPS
            and not _degenerate(int(m.geom_type[g]), size[g]) for g in range(m.ngeom)], bool)
        static = m.body_weldid[m.geom_bodyid] == 0

        # Pixel grid: centres of an OpenGL viewport, row 0 at the top. MuJoCo's frustum has
        # half-height tan(fovy/2) and half-width scaled by the viewport's aspect ratio.
        ty = math.tan(math.radians(camera.fovy) / 2)
        tx = ty * self.width / self.height
        self._u = ((2 * (np.arange(self.width) + 0.5) / self.width - 1) * tx).astype(np.float32)
        self._v = ((1 - 2 * (np.arange(self.height) + 0.5) / self.height) * ty).astype(np.float32)
        self._ia = (1.0 / (1.0 + self._u[None, :] ** 2 + self._v[:, None] ** 2)).astype(np.float32)
        pos, fwd, right, up = camera_frame(camera)
        light = -fwd + np.array([0.0, 0.0, 1.0])
        light = light / np.linalg.norm(light) if np.linalg.norm(light) > 1e-6 else -fwd
        # rows: camera position, forward, right, up, light (all transformed per geom per frame)
        self._cam = np.stack([pos, fwd, right, up, light]).astype(np.float32)
        self._znear = float(m.vis.map.znear * m.stat.extent)
        self._zfar = float(m.vis.map.zfar * m.stat.extent)

        self._rgb = rgba[:, :3].astype(np.float32)
        self._label = geom_label
        self._size = size.astype(np.float32)
        # 1/size where used (sphere/capsule/cylinder radius, ellipsoid axes); 0 elsewhere
        self._size_inv = np.where(size > 0, 1.0 / np.where(size > 0, size, 1.0), 0.0).astype(np.float32)
        self._type = np.array(m.geom_type, np.int64)

        # Static part: cast once with the poses of a forward pass at qpos0.
        d = mujoco.MjData(m)
        mujoco.mj_forward(m, d)
        sidx = np.flatnonzero(drawn & static)
        bg = np.array(BACKGROUND_RGB, np.uint8)
        if len(sidx):
            sidx = sidx[np.argsort(self._type[sidx], kind="stable")]
            # jitted: one compile is much cheaper than dispatching dozens of eager ops
            cast = jax.jit(lambda xp, xm: self._cast(sidx, xp, xm))(
                jnp.asarray(d.geom_xpos, jnp.float32),
                jnp.asarray(d.geom_xmat.reshape(-1, 3, 3), jnp.float32))
            ts = np.concatenate([np.asarray(t) for t, _ in cast])  # exact argmin: runs once
            coss = np.concatenate([np.asarray(c) for _, c in cast])
            k = np.argmin(ts, axis=0)
            t = np.take_along_axis(ts, k[None], 0)[0]
            cos = np.take_along_axis(coss, k[None], 0)[0]
            gid = sidx[k]
            hit = t < _MISS / 2
            shade = np.asarray(self._shade(self._rgb[gid], cos))
            self._static_t = np.where(hit, t, np.inf).astype(np.float32)
            self._static_rgb = np.where(hit[..., None], shade, bg).astype(np.uint8)
            self._static_label = np.where(hit, self._label[gid], 0).astype(np.int32)
        else:
            self._static_t = np.full((self.height, self.width), np.inf, np.float32)
            self._static_rgb = np.broadcast_to(bg, (self.height, self.width, 3)).copy()
            self._static_label = np.zeros((self.height, self.width), np.int32)
        moving = np.flatnonzero(drawn & ~static)
        self._moving = moving[np.argsort(self._type[moving], kind="stable")]  # grouped by type
        self._index_bits = max(1, (len(self._moving) - 1).bit_length())
        if self._index_bits > 8:  # the packed depth would get too coarse (see _pack)
            raise ValueError(f"{len(self._moving)} visible moving geoms: at most 256 supported")
        self._moving_rgbl = np.concatenate(
            [self._rgb[self._moving], self._label[self._moving, None].astype(np.float32)], 1)

    @staticmethod
    def _shade(rgb, cos):
        """float colour in [0,1] and n.l -> uint8-ready values (rounded, in [0,255])."""
        inten = AMBIENT + DIFFUSE * jnp.clip(cos, 0.0, 1.0)
        return jnp.clip(jnp.round(rgb * inten[..., None] * 255.0), 0, 255)

    def _cast(self, idx: np.ndarray, xpos, xmat):
        """Cast geoms `idx` (numpy int array, non-empty, sorted by type).

        Returns a list with one (t [G_type,h,w], n.l [G_type,h,w]) pair per geom type, in the
        order of `idx`; t is the eye-space depth, _MISS where a ray misses or is clipped.
        """
        types = self._type[idx]
        p, rot = xpos[idx], xmat[idx]  # [G,3], [G,3,3]; local = rot^T world
        cam = jnp.asarray(self._cam)
        # per geom, in its local frame: ray origin, forward, right, up, light direction [G,3] each
        o_l = jnp.einsum("gji,gj->gi", rot, cam[0][None] - p)
        f_l, r_l, up_l, l_l = (jnp.einsum("gji,j->gi", rot, cam[k]) for k in range(1, 5))
        size, size_inv = jnp.asarray(self._size[idx]), jnp.asarray(self._size_inv[idx])
        u = jnp.asarray(self._u)[None, None, :]
        v = jnp.asarray(self._v)[None, :, None]
        ia = jnp.asarray(self._ia)[None]
        out = []
        for gtype in np.unique(types):
            i0, i1 = np.flatnonzero(types == gtype)[[0, -1]]
            # per-geom scalars as 3 arrays [G_type,1,1] (x/y/z kept apart: elementwise only)
            col = lambda x: [x[i0:i1 + 1, k, None, None] for k in range(3)]  # noqa: E731
            o, f, r, up = col(o_l), col(f_l), col(r_l), col(up_l)
            d = [f[k] + r[k] * u + up[k] * v for k in range(3)]  # [G_type,h,w]
            t, cos = _HIT[int(gtype)](o, d, col(size), col(size_inv), col(l_l), ia)
            # t is the eye-space depth (forward . d = 1): clip like OpenGL's near/far planes.
            out.append((jnp.where((t > self._znear) & (t < self._zfar), t, _MISS), cos))
        return out

    def render(self, geom_xpos, geom_xmat) -> tuple[jax.Array, jax.Array]:
        """geom_xpos float32[ngeom,3], geom_xmat float32[ngeom,3,3] (as in mjx.Data) ->
        (rgb uint8[height,width,3], labels int32[height,width]). Pure; jit/vmap-able."""
        static_rgb = jnp.asarray(self._static_rgb)
        static_label = jnp.asarray(self._static_label)
        if not len(self._moving):
            return static_rgb, static_label
        xpos = jnp.asarray(geom_xpos, jnp.float32)
        xmat = jnp.reshape(jnp.asarray(geom_xmat, jnp.float32), (-1, 3, 3))
        nb = self._index_bits
        keys, i0 = [], 0
        for t, cos in self._cast(self._moving, xpos, xmat):
            ids = jnp.arange(i0, i0 + t.shape[0], dtype=jnp.int32)[:, None, None]
            keys.append(_pack(t, cos, ids, nb))
            i0 += t.shape[0]
        t, cos, k = _unpack(jnp.min(jnp.concatenate(keys, 0), axis=0), nb)
        front = (t < _MISS / 2) & (t < jnp.asarray(self._static_t))
        # one gather of (r, g, b, label) for the winning geom
        rgbl = jnp.asarray(self._moving_rgbl)[k]
        rgb = self._shade(rgbl[..., :3], cos).astype(jnp.uint8)
        rgb = jnp.where(front[..., None], rgb, static_rgb)
        labels = jnp.where(front, rgbl[..., 3].astype(jnp.int32), static_label)
        return rgb, labels
