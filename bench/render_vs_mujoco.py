"""Compare the JAX ray caster (envs_mjx.render) with MuJoCo's OpenGL renderer.

Builds a small scene with every primitive type (finite + infinite plane, sphere, capsule,
ellipsoid, cylinder, box; static geoms on the world body and moving ones on jointed bodies, plus
hidden group-3 / alpha-0 proxies), renders random poses with both renderers under several cameras
and compares per-pixel geom ids (MuJoCo: segmentation rendering) and 0/1/2 labels.
Pixels on a geom-id edge in MuJoCo's image (any 4-neighbour differs) are reported separately.
Then, if envs_mjx.make works, the same label comparison on each task scene (env.mj_model,
env.camera, env.geom_label) in states from env.reset with random arm joint offsets.

Finally it times the JAX renderer (48x48, jit, 1 env and vmapped over 64 envs) on the test
scene and the task scenes, next to MuJoCo's OSMesa renderer on the same scene as a reference
(the load average is recorded: timings on a shared CPU are noisy; the best of several runs is kept).

    MUJOCO_GL=osmesa PYOPENGL_PLATFORM=osmesa python -m bench render_vs_mujoco [--states 20]

(needs the Debian package libosmesa6; the two variables are set here when unset). Writes
bench/results/render_vs_mujoco.json.
"""

from __future__ import annotations

import argparse
import json
import os
import time

os.environ.setdefault("MUJOCO_GL", "osmesa")
os.environ.setdefault("PYOPENGL_PLATFORM", "osmesa")
os.environ.setdefault("JAX_PLATFORMS", "cpu")

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from bench.common import machine_info, result_path, write_result  # noqa: E402
from envs_mjx.render import Camera, Renderer  # noqa: E402

SCENE = """
<mujoco>
  <worldbody>
    <geom name="floor" type="plane" size="0 0 0.1" rgba="0.6 0.6 0.6 1"/>
    <geom name="table" type="plane" pos="0 0 0.001" size="0.4 0.3 0.1" rgba="0.3 0.5 0.3 1"/>
    <geom name="wall" type="box" pos="0.25 0.2 0.045" size="0.05 0.1 0.04" rgba="0.7 0.7 0.2 1"/>
    <geom name="post" type="cylinder" pos="-0.3 0.25 0.1" size="0.03 0.1" rgba="0.2 0.6 0.7 1"/>
    <geom name="hidden_proxy" type="box" pos="0 0 0.05" size="0.2 0.2 0.05" rgba="0 0 0 0" group="3"/>
    <body name="pedestal" pos="-0.3 -0.25 0">
      <geom name="ped" type="capsule" fromto="0 0 0 0 0 0.15" size="0.03" rgba="0.5 0.2 0.6 1"/>
    </body>
    <body name="ball" pos="0 0 0.05"><freejoint/>
      <geom name="ball" type="sphere" size="0.04" rgba="0.9 0.3 0.2 1"/></body>
    <body name="pill" pos="0.1 0 0.05"><freejoint/>
      <geom name="pill" type="capsule" size="0.025 0.05" rgba="0.2 0.3 0.9 1"/></body>
    <body name="egg" pos="-0.1 0 0.05"><freejoint/>
      <geom name="egg" type="ellipsoid" size="0.05 0.03 0.02" rgba="0.9 0.9 0.9 1"/></body>
    <body name="puck" pos="0 0.1 0.05"><freejoint/>
      <geom name="puck" type="cylinder" size="0.04 0.015" rgba="0.1 0.8 0.3 1"/>
      <geom name="puck_proxy" type="sphere" size="0.05" rgba="1 0 0 0" group="3"/></body>
    <body name="crate" pos="0 -0.1 0.05"><freejoint/>
      <geom name="crate" type="box" size="0.03 0.05 0.02" rgba="0.8 0.5 0.1 1"/></body>
    <body name="arm" pos="0 -0.2 0.2">
      <joint name="yaw" type="hinge" axis="0 0 1"/>
      <joint name="pitch" type="hinge" axis="1 0 0"/>
      <geom name="link" type="capsule" fromto="0 0 0 0 0.2 0" size="0.02" rgba="0.6 0.1 0.1 1"/>
      <geom name="knob" type="cylinder" size="0.03 0.03" euler="0 90 0" rgba="0.2 0.2 0.2 1"/>
      <body name="hand" pos="0 0.2 0">
        <geom name="finger" type="box" size="0.01 0.01 0.04" pos="0 0 -0.04" rgba="0.5 0.5 0.5 1"/>
      </body>
    </body>
    <body name="target" mocap="true" pos="0.15 0.15 0.12">
      <geom name="marker" type="sphere" size="0.015" rgba="1 1 0 1" contype="0" conaffinity="0"/>
    </body>
  </worldbody>
</mujoco>
"""

CAMERAS = {
    "push": Camera(lookat=(0.0, 0.0, 0.05), distance=0.6, elevation=-45.0, azimuth=270.0),
    "top": Camera(lookat=(0.0, 0.0, 0.0), distance=0.8, elevation=-89.0, azimuth=90.0),
    "side": Camera(lookat=(0.0, 0.0, 0.08), distance=0.7, elevation=-10.0, azimuth=200.0),
    "oblique": Camera(lookat=(0.05, -0.05, 0.05), distance=0.5, elevation=-30.0, azimuth=35.0),
}


def random_state(m, d, rng):
    """Random but plausible poses: free bodies scattered over the table, random arm angles."""
    mujoco.mj_resetData(m, d)
    for name in ("ball", "pill", "egg", "puck", "crate"):
        adr = m.jnt_qposadr[m.body_jntadr[m.body(name).id]]
        d.qpos[adr:adr + 3] = [rng.uniform(-0.2, 0.2), rng.uniform(-0.2, 0.2), rng.uniform(0.03, 0.12)]
        q = rng.normal(size=4)
        d.qpos[adr + 3:adr + 7] = q / np.linalg.norm(q)
    d.qpos[m.jnt_qposadr[m.joint("yaw").id]] = rng.uniform(-1.5, 1.5)
    d.qpos[m.jnt_qposadr[m.joint("pitch").id]] = rng.uniform(-0.6, 0.6)
    mujoco.mj_forward(m, d)


def edge_mask(ids):
    e = np.zeros(ids.shape, bool)
    e[1:] |= ids[1:] != ids[:-1]
    e[:-1] |= ids[1:] != ids[:-1]
    e[:, 1:] |= ids[:, 1:] != ids[:, :-1]
    e[:, :-1] |= ids[:, 1:] != ids[:, :-1]
    return e


def mujoco_ids(mj_r, d, cam):
    """Per-pixel geom id (-1: none) from MuJoCo's segmentation rendering."""
    mcam = mujoco.MjvCamera()
    mcam.type = mujoco.mjtCamera.mjCAMERA_FREE
    mcam.lookat[:] = cam.lookat
    mcam.distance, mcam.elevation, mcam.azimuth = cam.distance, cam.elevation, cam.azimuth
    mj_r.update_scene(d, camera=mcam)
    seg = mj_r.render()
    return np.where((seg[..., 1] == int(mujoco.mjtObj.mjOBJ_GEOM)) & (seg[..., 0] >= 0), seg[..., 0], -1)


def _task_states(env, d, rng):
    """states(i) puts C MjData `d` in env.reset's state for key i, arm joints offset at random."""
    m = env.mj_model
    reset = jax.jit(env.reset)
    arm = np.array([m.joint(j).qposadr[0] for j in range(m.njnt)
                    if m.joint(j).name.startswith("j") and m.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE])

    def states(i):
        s = reset(jax.random.PRNGKey(i))
        mujoco.mj_resetData(m, d)
        d.qpos[:] = np.asarray(s.data.qpos)
        d.mocap_pos[:] = np.asarray(s.data.mocap_pos)
        d.mocap_quat[:] = np.asarray(s.data.mocap_quat)
        if len(arm):
            d.qpos[arm] += rng.uniform(-0.2, 0.2, len(arm))
        mujoco.mj_forward(m, d)
    return states


def task_scenes(n_states: int = 20, size: int = 48):
    """Label agreement on the task scenes built by envs_mjx (skipped if they do not build)."""
    try:
        import envs_mjx
        names = envs_mjx.TASK_NAMES
    except Exception as e:  # the scenes are developed separately; this script must not depend on them
        print(f"task scenes skipped: {e!r}")
        return {"skipped": repr(e)}
    rng = np.random.default_rng(1)
    out = {}
    for name in names:
        env = envs_mjx.make(name)
        m = env.mj_model
        d = mujoco.MjData(m)
        label = np.asarray(env.geom_label)
        states = _task_states(env, d, rng)
        render = jax.jit(Renderer(m, env.camera, label, width=size, height=size).render)
        mj_r = mujoco.Renderer(m, height=size, width=size)
        mj_r.enable_segmentation_rendering()
        agree = total = 0
        for i in range(n_states):
            states(i)
            ids = mujoco_ids(mj_r, d, env.camera)
            want = np.where(ids >= 0, label[np.maximum(ids, 0)], 0)
            _, lab = render(d.geom_xpos.astype(np.float32), d.geom_xmat.reshape(-1, 3, 3).astype(np.float32))
            agree += (np.asarray(lab) == want).sum()
            total += want.size
        mj_r.close()
        out[name] = {"label_agreement": agree / total,
                     "pixels_per_label_last_state": np.bincount(want.ravel(), minlength=3).tolist()}
        print(f"task {name:14s} {size}x{size} label agree {agree / total:.4f}", flush=True)
    return out


def _best_us_per_image(f, args, batch, reps=15, min_s=0.05):
    """Best over `reps` timed runs of the time per image, in us: (wall, process CPU time).

    CPU time (all threads) is less sensitive to other jobs on a shared machine than wall time.
    """
    jax.block_until_ready(f(*args))
    n = 1
    while True:  # calibrate the number of calls per run
        t0 = time.perf_counter()
        for _ in range(n):
            out = f(*args)
        jax.block_until_ready(out)
        if time.perf_counter() - t0 > min_s:
            break
        n *= 2
    wall = cpu = float("inf")
    for _ in range(reps):
        t0, c0 = time.perf_counter(), time.process_time()
        for _ in range(n):
            out = f(*args)
        jax.block_until_ready(out)
        wall = min(wall, (time.perf_counter() - t0) / n / batch)
        cpu = min(cpu, (time.process_time() - c0) / n / batch)
    return wall * 1e6, cpu * 1e6


def _poses(m, d, states, n=64):
    xs, ms = [], []
    for i in range(n):
        states(i)
        xs.append(d.geom_xpos.astype(np.float32))
        ms.append(d.geom_xmat.reshape(-1, 3, 3).astype(np.float32))
    return jnp.asarray(np.stack(xs)), jnp.asarray(np.stack(ms))


def speed(size: int = 48):
    """us per image: JAX renderer at 1 and 64 envs; MuJoCo (OSMesa, RGB) on the same scene."""
    scenes = []
    m = mujoco.MjModel.from_xml_string(SCENE)
    d = mujoco.MjData(m)
    rng = np.random.default_rng(2)
    scenes.append(("test_scene", m, d, CAMERAS["push"], np.arange(1, m.ngeom + 1),
                   lambda i, m=m, d=d: random_state(m, d, rng)))
    try:
        import envs_mjx
        for name in envs_mjx.TASK_NAMES:
            env = envs_mjx.make(name)
            de = mujoco.MjData(env.mj_model)
            scenes.append((name, env.mj_model, de, env.camera, np.asarray(env.geom_label),
                           _task_states(env, de, rng)))
    except Exception as e:
        print(f"task scenes skipped in timing: {e!r}")
    out = {"loadavg_before": os.getloadavg(), "cpu_count": os.cpu_count(), "size": size}
    for name, m, d, cam, label, states in scenes:
        r = Renderer(m, cam, label, width=size, height=size)
        xs, ms = _poses(m, d, states)
        single = jax.jit(r.render)
        batched = jax.jit(jax.vmap(r.render))
        us1, cpu1 = _best_us_per_image(single, (xs[0], ms[0]), 1)
        us64, cpu64 = _best_us_per_image(batched, (xs, ms), 64)
        mj_r = mujoco.Renderer(m, height=size, width=size)
        mcam = mujoco.MjvCamera()
        mcam.type = mujoco.mjtCamera.mjCAMERA_FREE
        mcam.lookat[:] = cam.lookat
        mcam.distance, mcam.elevation, mcam.azimuth = cam.distance, cam.elevation, cam.azimuth

        def mj_render():
            mj_r.update_scene(d, camera=mcam)
            return mj_r.render()
        mj_render()
        best = best_cpu = float("inf")
        for _ in range(5):
            t0, c0 = time.perf_counter(), time.process_time()
            for _ in range(20):
                mj_render()
            best = min(best, (time.perf_counter() - t0) / 20)
            best_cpu = min(best_cpu, (time.process_time() - c0) / 20)
        mj_r.close()
        out[name] = {"moving_geoms": int(len(r._moving)),
                     "jax_us_per_image_1env": us1, "jax_us_per_image_64envs": us64,
                     "jax_cpu_us_per_image_1env": cpu1, "jax_cpu_us_per_image_64envs": cpu64,
                     "mujoco_osmesa_us_per_image": best * 1e6,
                     "mujoco_osmesa_cpu_us_per_image": best_cpu * 1e6,
                     "speedup_64envs_vs_mujoco": best * 1e6 / us64}
        print(f"speed {name:14s} {len(r._moving):2d} moving geoms: wall {us1:6.1f} us/image (1 env), "
              f"{us64:5.1f} (64 envs) [CPU time {cpu1:6.1f}, {cpu64:5.1f}]; "
              f"MuJoCo OSMesa wall {best * 1e6:7.1f} [CPU {best_cpu * 1e6:7.1f}]", flush=True)
    out["loadavg_after"] = os.getloadavg()
    return out


def main(argv=None, sizes=((48, 48), (128, 96))):
    p = argparse.ArgumentParser(prog="python -m bench render_vs_mujoco", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--states", type=int, default=20, help="random states per camera and size")
    p.add_argument("--out", default=result_path("render_vs_mujoco"), help="result file")
    a = p.parse_args(argv)
    n_states = a.states
    machine = machine_info()
    m = mujoco.MjModel.from_xml_string(SCENE)
    d = mujoco.MjData(m)
    # label = geom id + 1 so the JAX renderer's labels are geom ids; 0/1/2 labels derived below
    gid_label = np.arange(1, m.ngeom + 1, dtype=np.int32)
    robot = {m.geom(n).id for n in ("link", "knob", "finger")}
    objects = {m.geom(n).id for n in ("ball", "pill", "egg", "puck", "crate")}
    label012 = np.array([1 if g in robot else 2 if g in objects else 0 for g in range(m.ngeom)])
    rng = np.random.default_rng(0)
    results = {}
    for (w, h) in sizes:
        mj_r = mujoco.Renderer(m, height=h, width=w)
        mj_r.enable_segmentation_rendering()
        for cname, cam in CAMERAS.items():
            jr = Renderer(m, cam, gid_label, width=w, height=h)
            render = jax.jit(jr.render)
            agree = edge_agree = interior = total = lab_agree = 0
            for _ in range(n_states):
                random_state(m, d, rng)
                mj_ids = mujoco_ids(mj_r, d, cam)
                _, lab = render(d.geom_xpos.astype(np.float32),
                                d.geom_xmat.reshape(-1, 3, 3).astype(np.float32))
                ours = np.asarray(lab) - 1
                eq = ours == mj_ids
                e = edge_mask(mj_ids)
                agree += eq.sum()
                total += eq.size
                interior += (~e).sum()
                edge_agree += (eq & ~e).sum()
                lab_agree += (np.where(ours >= 0, label012[np.maximum(ours, 0)], 0)
                              == np.where(mj_ids >= 0, label012[np.maximum(mj_ids, 0)], 0)).sum()
            key = f"{cname}_{w}x{h}"
            results[key] = {
                "geom_id_agreement": agree / total,
                "geom_id_agreement_off_edges": edge_agree / interior,
                "label_agreement": lab_agree / total,
            }
            print(f"{key:16s} geom id agree {agree / total:.4f}  (off edges {edge_agree / interior:.4f})"
                  f"  labels {lab_agree / total:.4f}", flush=True)
        mj_r.close()
    col = lambda k: [r[k] for r in results.values()]  # noqa: E731
    summary = {
        "mean_geom_id_agreement": float(np.mean(col("geom_id_agreement"))),
        "mean_geom_id_agreement_off_edges": float(np.mean(col("geom_id_agreement_off_edges"))),
        "mean_label_agreement": float(np.mean(col("label_agreement"))),
        "min_label_agreement": float(np.min(col("label_agreement"))),
    }
    print(json.dumps(summary, indent=1))
    tasks = task_scenes(n_states)
    write_result("render_vs_mujoco", {"per_case": results, "summary": summary,
                                      "task_scenes": tasks, "speed": speed(),
                                      "n_states_per_case": n_states}, machine, argv, a.out)


if __name__ == "__main__":
    main()
