"""MuJoCo physics, rendering and colour tracking: how fast.

- PhysicsWorld with 1, 10, 100 ground robots (unicycle servo, contacts on,
  10 ms block period = 5 MuJoCo steps of 2 ms): block updates per second
  and MuJoCo steps per second, and the same for quadrotors;
- SceneCamera renders per second at 160x120, 320x240, 640x480 (offscreen
  buffer = image size), shadows/reflections off and on;
- ColorBlobTracker milliseconds per image (one image, and a batch of 10).

Both wall-clock and process-CPU time are reported: on a shared machine the
CPU figure is the steadier one. The GL backend in use is printed (EGL on a
GPU is much faster than Mesa's software rasterizer).

Run: ``python benchmarks/physics.py [--quick] [--png out.png]``; prints
markdown tables.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np


def timeit(fn, min_time=1.0, max_reps=100000):
    fn()
    reps, t0, c0 = 0, time.perf_counter(), time.process_time()
    while True:
        fn()
        reps += 1
        el = time.perf_counter() - t0
        if el >= min_time or reps >= max_reps:
            return el / reps, (time.process_time() - c0) / reps


def physics(n, kind, min_time):
    from avblocks.interfaces.mujoco import PhysicsWorld, Scene
    from avblocks.utility import random_poses
    s = Scene()
    side = max(4.0, 2.0 * np.sqrt(n))
    if kind == "ground":
        p0 = random_poses(n, (side, side), min_separation=0.6, seed=1)
        s.add_ground_robots("r", p0, radius=0.2)
        port, u = "cmd", np.tile([0.5, 0.3], (n, 1))
    else:
        p0 = np.column_stack([random_poses(n, (side, side), min_separation=0.8, seed=1)[:, :2],
                              np.full(n, 2.0)])
        s.add_quadrotors("q", p0)
        port, u = "wrench", np.tile([9.81, 0.0, 0.0, 0.0], (n, 1))
    b = PhysicsWorld(s, period=0.01)
    state = {"x": b.initial_state(), "t": 0.0}

    def step():
        state["x"] = b.update(state["t"], state["x"], {port: u}, np)
        b.output(state["t"], state["x"], {}, np)
        state["t"] += 0.01
    wall, cpu = timeit(step, min_time)
    return wall, cpu, b.nsub


def render(width, height, shadows, min_time):
    from avblocks.environment import Circle, World, rectangle
    from avblocks.interfaces.mujoco import Scene, SceneCamera
    w = World([rectangle(1, 1, 2.5, 2), Circle((-1, 3), 0.6), rectangle(-4, -1, -3, 1.5)])
    s = Scene(w, max_image=(width, height), shadows=shadows)
    s.add_ground_robots("r", [[0.0, 0.0, 0.0], [1.0, -1.0, 1.0]], color=(0.9, 0.1, 0.1))
    s.add_camera("top", (0.0, -8.0, 9.0), (0.0, 0.0, 0.0))
    cam = SceneCamera(s, "top", width=width, height=height, shadows=shadows,
                      reflections=shadows)
    u = {"r_pose": np.array([[0.0, 0.0, 0.0], [1.0, -1.0, 1.0]])}
    return timeit(lambda: cam.render(u), min_time, 2000)


def tracker(n, width, height, min_time):
    from avblocks.interfaces.vision import ColorBlobTracker
    rng = np.random.default_rng(0)
    imgs = rng.integers(60, 140, (n, height, width, 3), dtype=np.uint8)
    yy, xx = np.mgrid[0:height, 0:width]
    for k in range(n):
        m = (xx - width * 0.4) ** 2 + (yy - height * 0.6) ** 2 < (0.05 * width) ** 2
        imgs[k][m] = (220, 20, 20)
    tr = ColorBlobTracker.red(n, height, width)
    return timeit(lambda: tr.output(0.0, {}, {"image": imgs}, np), min_time)


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--png", default=None)
    a = ap.parse_args(argv)
    mt = 0.3 if a.quick else 1.5
    from avblocks.interfaces.mujoco import choose_backend, import_mujoco
    mj = import_mujoco()
    print(f"MuJoCo {mj.__version__}, MUJOCO_GL={choose_backend()}, "
          f"{os.cpu_count()} CPUs, load {os.getloadavg()[0]:.1f}\n")
    print("| agents | kind | block updates/s (wall) | MuJoCo steps/s (wall) | "
          "ms/update (CPU) | sim-time x real (CPU) |")
    print("|---:|---|---:|---:|---:|---:|")
    rows = []
    for kind in ("ground", "quad"):
        for n in (1, 10, 100):
            wall, cpu, nsub = physics(n, kind, mt)
            rows.append((kind, n, wall, cpu))
            print(f"| {n} | {kind} | {1 / wall:,.0f} | {nsub / wall:,.0f} | {cpu * 1e3:.3f} | "
                  f"{0.01 / cpu:,.0f} |")
    print("\n| image | shadows+reflections | renders/s (wall) | ms/render (CPU) |")
    print("|---|---|---:|---:|")
    rrows = []
    for (wd, ht) in ((160, 120), (320, 240), (640, 480)):
        for sh in (False, True):
            wall, cpu = render(wd, ht, sh, mt)
            rrows.append((wd, ht, sh, wall))
            print(f"| {wd}x{ht} | {'on' if sh else 'off'} | {1 / wall:,.1f} | {cpu * 1e3:.2f} |")
    print("\n| images | size | tracker ms/image (wall) | ms/image (CPU) |")
    print("|---:|---|---:|---:|")
    for n in (1, 10):
        for (wd, ht) in ((160, 120), (320, 240), (640, 480)):
            wall, cpu = tracker(n, wd, ht, mt)
            print(f"| {n} | {wd}x{ht} | {wall / n * 1e3:.3f} | {cpu / n * 1e3:.3f} |")
    if a.png:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, ax = plt.subplots(1, 2, figsize=(9, 3.6))
        for kind in ("ground", "quad"):
            r = [x for x in rows if x[0] == kind]
            ax[0].loglog([x[1] for x in r], [1 / x[2] for x in r], "o-", label=kind)
        ax[0].set_xlabel("agents")
        ax[0].set_ylabel("block updates / s (10 ms each)")
        ax[0].axhline(100, color="k", lw=0.6, ls="--")
        ax[0].text(1, 110, "real time", fontsize=8)
        ax[0].legend()
        ax[0].grid(alpha=0.3, which="both")
        labels = [f"{w}x{h}\n{'shadows' if s else 'plain'}" for w, h, s, _ in rrows]
        ax[1].bar(range(len(rrows)), [1 / x[3] for x in rrows])
        ax[1].set_xticks(range(len(rrows)), labels, fontsize=7)
        ax[1].set_ylabel("renders / s")
        fig.suptitle(f"MuJoCo physics and rendering (MUJOCO_GL={choose_backend()})")
        fig.tight_layout()
        fig.savefig(a.png, dpi=110)
        print(f"\nwrote {a.png}")


if __name__ == "__main__":
    main()
