"""Reproduce the AVLib paper's Figure 3: wall time to simulate 30 s
(dt = 10 ms) of N unicycles under a go-to-goal law.

Compared:
  legacy   a Python loop over agents (math module, one agent at a time)
  numpy    the same law as a plain vectorized NumPy loop (Euler)
  euler    avblocks, Unicycle + PointToPoint diagram, Euler
  rk4      avblocks, same diagram, RK4

Each case is the best of 3 runs (1 for the legacy loop). Long cases are timed
over fewer steps and scaled to the 3000 steps of 30 s (marked with *); pass
--full to run every case to the end.

    python benchmarks/scaling.py            # table + benchmarks/scaling.png
    python benchmarks/scaling.py --quick    # N up to 3000

With ``--backend jax`` (or ``all``) it measures the compiled backend on the
same workload (W1: Unicycle + PointToPoint, Euler, dt 10 ms, 3000 steps)
against a fused Numba loop of the same math (numba: a benchmark-only
dependency) and the NumPy engine: first call including trace and compile at
N = 1000, second calls at N = 10 .. 1e5, real-time factors, and an ensemble
of 256 runs x 100 agents (one vmapped program) against 256 sequential NumPy
runs. It writes the table and benchmarks/scaling_backends.png.

    python benchmarks/scaling.py --backend jax [--quick]

``--ratios`` measures only the NumPy engine / plain NumPy ratio, from
alternating runs (the steady figure on a shared machine).
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import numpy as np

import avblocks as av

T_FINAL, DT = 30.0, 0.01
STEPS = int(round(T_FINAL / DT))
D, K, VMAX, R = 0.1, 1.0, 1.0, 0.2


def setup(n, seed=1):
    rng = np.random.default_rng(seed)
    p0 = np.column_stack([rng.uniform(0, 100, (n, 2)), rng.uniform(-np.pi, np.pi, n)])
    goal = rng.uniform(0, 100, (n, 2))
    return p0, goal


def legacy(n, steps):
    p0, goal = setup(n)
    pose = [list(p) for p in p0]
    g = [tuple(q) for q in goal]
    done = [False] * n
    for _ in range(steps):
        for i in range(n):
            x, y, th = pose[i]
            c, s = math.cos(th), math.sin(th)
            ex, ey = g[i][0] - x - D * c, g[i][1] - y - D * s
            done[i] = done[i] or ex * ex + ey * ey <= R * R
            wx, wy = K * ex, K * ey
            nrm = math.hypot(wx, wy)
            if nrm > VMAX:
                wx, wy = wx * VMAX / nrm, wy * VMAX / nrm
            v = c * wx + s * wy
            w = (-s * wx + c * wy) / D
            pose[i] = [x + DT * v * c, y + DT * v * s, th + DT * w]
    return pose


def plain_numpy(n, steps):
    pose, goal = setup(n)
    done = np.zeros(n, bool)
    for _ in range(steps):
        th = pose[:, 2]
        c, s = np.cos(th), np.sin(th)
        ex = goal[:, 0] - pose[:, 0] - D * c
        ey = goal[:, 1] - pose[:, 1] - D * s
        done |= ex * ex + ey * ey <= R * R
        wx, wy = K * ex, K * ey
        scale = np.minimum(1.0, VMAX / np.maximum(np.hypot(wx, wy), 1e-300))
        wx, wy = wx * scale, wy * scale
        v = c * wx + s * wy
        w = (-s * wx + c * wy) / D
        pose = pose + DT * np.column_stack([v * c, v * s, w])
    return pose


def diagram(n):
    p0, goal = setup(n)
    d = av.Diagram()
    fleet = d.add(av.vehicles.Unicycle(pose0=p0), name="fleet")
    drive = d.add(av.controllers.PointToPoint(goal[:, None, :], d=D, gain=K, v_max=VMAX,
                                              radius=R), name="drive")
    d.connect(fleet.pose, drive.pose)
    d.connect(drive.cmd, fleet.cmd)
    return d, fleet


def avblocks_run(solver):
    def run(n, steps):
        d, fleet = diagram(n)
        return av.simulate(d, steps * DT, dt=DT, solver=solver, log=[fleet.pose],
                           log_every=max(1, steps // 30), progress=False)
    return run


CLOCK = time.perf_counter    # --clock cpu: time.process_time (shared machines)


def time_it(fn, n, steps, repeat=1):
    """Best of ``repeat`` runs (the machine's noise only ever adds time)."""
    best = math.inf
    for _ in range(repeat):
        t0 = CLOCK()
        fn(n, steps)
        best = min(best, CLOCK() - t0)
    return best


def budget_steps(kind, n, full):
    if full:
        return STEPS
    work = {"legacy": 4e6, "numpy": 1e8, "euler": 1e8, "rk4": 3e7}[kind]
    return int(min(STEPS, max(50, work // max(n, 1))))


def numba_loop():
    """The W1 law and Euler step fused into one compiled loop (Numba)."""
    import numba

    @numba.njit(cache=False, fastmath=False)
    def loop(pose, goal, steps):
        n = pose.shape[0]
        done = np.zeros(n, np.bool_)
        for _ in range(steps):
            for i in range(n):
                x, y, th = pose[i, 0], pose[i, 1], pose[i, 2]
                c, s = math.cos(th), math.sin(th)
                ex = goal[i, 0] - x - D * c
                ey = goal[i, 1] - y - D * s
                if ex * ex + ey * ey <= R * R:
                    done[i] = True
                wx, wy = K * ex, K * ey
                nrm = math.hypot(wx, wy)
                if nrm > VMAX:
                    wx, wy = wx * VMAX / nrm, wy * VMAX / nrm
                v = c * wx + s * wy
                w = (c * wy - s * wx) / D
                pose[i, 0] = x + DT * v * c
                pose[i, 1] = y + DT * v * s
                pose[i, 2] = th + DT * w
        return pose

    def run(n, steps):
        p0, goal = setup(n)
        return loop(p0.copy(), goal, steps)
    run(2, 2)                       # compile outside the timings
    return run


def jax_loop():
    """The W1 law, Euler step and arrival latch written by hand as one JAX
    ``lax.scan`` (compiled with avblocks' XLA options): a naive reference.
    Its carry is two arrays, so XLA runs each step as two fused loops and a
    copy; avblocks' own program packs its carry and runs one loop per step
    (``avblocks.core.compiled.carry``), so it is now faster than this."""
    from avblocks.core.compiled import require_jax
    from avblocks.core.compiled.program import compile_lowered
    jax = require_jax()
    jnp = jax.numpy

    def run_(pose, goal, steps):
        def step(carry, _):
            pose, done = carry
            c, s = jnp.cos(pose[:, 2]), jnp.sin(pose[:, 2])
            ex = goal[:, 0] - pose[:, 0] - D * c
            ey = goal[:, 1] - pose[:, 1] - D * s
            done = done | (ex * ex + ey * ey <= R * R)
            wx, wy = K * ex, K * ey
            scale = jnp.minimum(1.0, VMAX / jnp.maximum(jnp.hypot(wx, wy), 1e-300))
            wx, wy = wx * scale, wy * scale
            v = c * wx + s * wy
            w = (c * wy - s * wx) / D
            return (pose + DT * jnp.stack([v * c, v * s, w], axis=1), done), None
        carry, _ = jax.lax.scan(step, (pose, jnp.zeros(pose.shape[0], bool)), None,
                                length=steps)
        return carry

    cache = {}

    def run(n, steps):
        p0, goal = setup(n)
        with jax.enable_x64(True):
            key = (n, steps)
            if key not in cache:
                cache[key] = compile_lowered(jax.jit(run_, static_argnums=2).lower(
                    p0, goal, steps))
            return jax.block_until_ready(cache[key](p0, goal))
    return run


def percall_main(args):
    """Per-call cost at small N: a second ``simulate(backend="jax")``, a
    ``Runner`` call, the hand-written JAX scan and the fused Numba loop,
    timed alternately (25 rounds, each starting with the next call; min and
    median)."""
    import os
    import statistics
    n, steps = 10, STEPS
    d, fleet = diagram(n)
    kw = dict(dt=DT, solver="euler", log=[fleet.pose], log_every=100)
    runner = av.compile(d, steps * DT, **kw)
    nb, hand = numba_loop(), jax_loop()
    cases = {"simulate(backend='jax')": lambda: av.simulate(d, steps * DT, backend="jax",
                                                             progress=False, **kw),
             "Runner call": runner, "hand-written JAX scan": lambda: hand(n, steps),
             "fused Numba loop": lambda: nb(n, steps)}
    times = {k: [] for k in cases}
    for f in cases.values():
        f()                                          # compile outside the timings
    order = list(cases)
    for r in range(25):
        # each round starts with another call: the first call of a round pays
        # more (a Runner call after the Numba loop measured 0.04 ms more than
        # after another JAX call), and a fixed order charged it to simulate
        for k in order[r % len(order):] + order[:r % len(order)]:
            t = time.perf_counter()
            cases[k]()
            times[k].append(time.perf_counter() - t)
    base = min(times["fused Numba loop"])
    print(f"\nPer-call cost, W1, N = {n}, Euler, {steps} steps, log every 100; 25 "
          f"alternating rounds (rotating order); load average {os.getloadavg()[0]:.1f}\n")
    print("| call | min ms | median ms | min / Numba |")
    print("|---|---:|---:|---:|")
    for k, v in times.items():
        print(f"| {k} | {min(v) * 1e3:.3f} | {statistics.median(v) * 1e3:.3f} | "
              f"{min(v) / base:.2f} |")


def jax_main(args):
    """The compiled backend vs a fused Numba loop and the NumPy engine."""
    import os

    if args.devices:
        os.environ["JAX_NUM_CPU_DEVICES"] = str(args.devices)
    from avblocks.core.compiled import _jax
    t = time.perf_counter()
    jax = _jax.jax()            # as avblocks starts it: one CPU device per core
    jax.numpy.zeros(1).block_until_ready()
    jax_init = time.perf_counter() - t
    load = os.getloadavg()[0]
    nb = numba_loop()
    ns = [10, 100, 1000, 10000] + ([] if args.quick else [100000])
    log_every = 100

    def jax_run(d, fleet, steps, **kw):
        return av.simulate(d, steps * DT, dt=DT, solver="euler", log=[fleet.pose],
                           log_every=log_every, backend="jax", **kw)

    # 1. first call (trace + compile + run) at N = 1000, fresh structure
    d, fleet = diagram(1000)
    t = time.perf_counter()
    r = jax_run(d, fleet, STEPS)
    first = time.perf_counter() - t
    compile_s = r.meta["compile_time"]
    # check: the compiled run matches the NumPy engine
    ref = av.simulate(d, 300 * DT, dt=DT, solver="euler", log=[fleet.pose], progress=False)
    got = av.simulate(d, 300 * DT, dt=DT, solver="euler", log=[fleet.pose], backend="jax")
    agree = float(np.max(np.abs(ref[fleet.pose] - got[fleet.pose])))
    rows = []
    for n in ns:
        d, fleet = diagram(n)
        jsteps = STEPS if n <= 10000 or args.full else 1000
        jax_run(d, fleet, jsteps)                                   # compile
        j = min(_wall(lambda d=d, f=fleet, s=jsteps: jax_run(d, f, s))
                for _ in range(3 if n <= 10000 else 1)) * STEPS / jsteps
        nbs = jsteps
        m = min(_wall(lambda n=n, s=nbs: nb(n, s))
                for _ in range(3 if n <= 10000 else 1)) * STEPS / nbs
        esteps = budget_steps("euler", n, args.full)
        e = time_it(avblocks_run("euler"), n, esteps, 1 if n > 10000 else 2) * STEPS / esteps
        psteps = budget_steps("numpy", n, args.full)
        p = time_it(plain_numpy, n, psteps, 1 if n > 10000 else 2) * STEPS / psteps
        rows.append((n, j, m, e, p, jsteps < STEPS, esteps < STEPS))
    # ensemble: 256 runs x 100 agents x 3000 steps, each run its own start poses
    R, na = 256, 100
    d, fleet = diagram(na)
    p0s = np.stack([setup(na, seed=s)[0] for s in range(R)])
    runner = av.compile(d, T_FINAL, dt=DT, solver="euler", log=[fleet.pose],
                        log_every=log_every)
    runner.ensemble(x0={"fleet.pose": p0s[:8]})                  # compile (R = 8)
    t = time.perf_counter()
    ens = runner.ensemble(x0={"fleet.pose": p0s})
    ens_first = time.perf_counter() - t
    t = time.perf_counter()
    runner.ensemble(x0={"fleet.pose": p0s})
    ens_wall = time.perf_counter() - t
    seq_runs = 8
    per_run = []
    for s in range(seq_runs):
        t = time.perf_counter()
        one = av.simulate(d, T_FINAL, dt=DT, solver="euler", log=[fleet.pose],
                          log_every=log_every, x0={"fleet.pose": p0s[s]}, progress=False)
        per_run.append(time.perf_counter() - t)
    seq = float(np.median(per_run)) * R          # median run: robust to the machine's noise
    ens_agree = float(np.max(np.abs(ens[fleet.pose][seq_runs - 1] - one[fleet.pose])))

    print(f"\nCompiled backend (JAX {jax.__version__}, {len(jax.devices())} "
          f"{jax.default_backend()} device(s)), "
          f"W1 = Unicycle + PointToPoint, Euler, dt = 10 ms, {STEPS} steps, log every "
          f"{log_every}; load average {load:.1f} on {os.cpu_count()} cores\n")
    print(f"JAX start-up (import + first op): {jax_init:.2f} s (once per process)")
    print(f"first simulate(backend='jax') at N = 1000: {first:.2f} s "
          f"(trace + compile {compile_s:.2f} s); matches NumPy engine to {agree:.1e}\n")
    print("| N | jax 2nd call s | fused Numba s | jax / Numba | avblocks NumPy s "
          "| plain NumPy s | NumPy engine / jax | RT factor (jax) |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|")
    for n, j, m, e, p, jest, eest in rows:
        print(f"| {n} | {j:.3g}{'*' if jest else ''} | {m:.3g} | {j / m:.2f} | "
              f"{e:.3g}{'*' if eest else ''} | {p:.3g}{'*' if eest else ''} | {e / j:.1f} "
              f"| {T_FINAL / j:.0f} |")
    print(f"\nensemble {R} runs x {na} agents x {STEPS} steps: {ens_wall:.2f} s "
          f"(first call {ens_first:.2f} s, {ens.meta['chunks']} chunk(s)); "
          f"{R} sequential NumPy runs: {seq:.1f} s* (median of {seq_runs} timed, x {R}); "
          f"speed-up {seq / ens_wall:.0f}x; run {seq_runs - 1} agrees to {ens_agree:.1e}")
    print("* timed over fewer steps or runs and scaled")
    xs = [r[0] for r in rows]
    jax_label = (f"avblocks, backend='jax' (2nd call, {len(jax.devices())} "
                 f"{jax.default_backend()} device(s))")
    _plot(xs, [([r[4] for r in rows], "s-", "plain NumPy loop"),
               ([r[3] for r in rows], "^-", "avblocks, NumPy engine"),
               ([r[1] for r in rows], "o-", jax_label),
               ([r[2] for r in rows], "d--", "fused Numba loop (1 thread)")],
          "W1: go-to-goal unicycles, Euler, dt = 10 ms",
          Path(args.out).with_name("scaling_backends.png"))


def ratios_main(args):
    """NumPy engine / plain NumPy measured side by side: the two runs
    alternate, 15 times, and each keeps its fastest (process CPU time), so a
    slow spell of a shared machine hits both alike."""
    steps, reps = 1000, 15
    print(f"\nNumPy engine / plain NumPy loop, W1, Euler, {steps} steps (log every 100), "
          f"best of {reps} alternating runs (process time; the diagram is built once)\n")
    print("| N | engine us/step | plain NumPy us/step | ratio |")
    print("|---:|---:|---:|---:|")
    for n in (10, 100, 1000, 3000, 10000):
        engine, plain = math.inf, math.inf
        d, fleet = diagram(n)
        for _ in range(reps):
            t = time.process_time()
            av.simulate(d, steps * DT, dt=DT, solver="euler", log=[fleet.pose],
                        log_every=100, progress=False)
            engine = min(engine, time.process_time() - t)
            t = time.process_time()
            plain_numpy(n, steps)
            plain = min(plain, time.process_time() - t)
        print(f"| {n} | {engine / steps * 1e6:.1f} | {plain / steps * 1e6:.1f} | "
              f"{engine / plain:.2f} |")


def _wall(fn):
    t = time.perf_counter()
    fn()
    return time.perf_counter() - t


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="N up to 3000 only")
    ap.add_argument("--full", action="store_true", help="run every case for 3000 steps")
    ap.add_argument("--percall", action="store_true",
                    help="only the per-call cost at N = 10 (simulate, Runner, "
                         "hand-written JAX, Numba)")
    ap.add_argument("--ratios", action="store_true",
                    help="only the NumPy engine / plain NumPy ratio, from alternating "
                         "runs (steady on a shared machine)")
    ap.add_argument("--backend", choices=("numpy", "jax", "all"), default="numpy",
                    help="numpy: the engines vs plain loops (default); jax: the compiled "
                         "backend vs a fused Numba loop; all: both")
    ap.add_argument("--out", default=str(Path(__file__).with_name("scaling.png")))
    ap.add_argument("--devices", type=int, default=0,
                    help="JAX CPU devices (default: avblocks' choice, one per core; "
                         "1 = JAX's own default, everything on one core)")
    ap.add_argument("--clock", choices=("wall", "cpu"), default="wall",
                    help="cpu: process CPU time, steadier on a loaded machine")
    args = ap.parse_args()
    global CLOCK
    CLOCK = time.process_time if args.clock == "cpu" else time.perf_counter
    if args.percall:
        percall_main(args)
        return
    if args.ratios:
        ratios_main(args)
        return
    if args.backend in ("jax", "all"):
        jax_main(args)
        if args.backend == "jax":
            return
    ns = [10, 30, 100, 300, 1000, 3000] + ([] if args.quick else [10000, 30000])
    kinds = {"legacy": legacy, "numpy": plain_numpy, "euler": avblocks_run("euler"),
             "rk4": avblocks_run("rk4")}
    rows = {}
    for n in ns:
        for kind, fn in kinds.items():
            steps = budget_steps(kind, n, args.full)
            wall = time_it(fn, n, steps, 1 if kind == "legacy" else 3) * STEPS / steps
            rows[(n, kind)] = (wall, steps < STEPS)
    print(f"\nWall time to simulate {T_FINAL:.0f} s at dt = {DT * 1e3:.0f} ms "
          f"({STEPS} steps); * = timed over fewer steps and scaled\n")
    print("| N | legacy s | numpy s | avblocks euler s | avblocks rk4 s | euler/numpy "
          "| legacy/euler | RT factor (euler) | ns/agent-step (euler) |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for n in ns:
        def f(kind, n=n):
            w, est = rows[(n, kind)]
            return f"{w:.3g}{'*' if est else ''}"
        e, npy, leg = rows[(n, "euler")][0], rows[(n, "numpy")][0], rows[(n, "legacy")][0]
        print(f"| {n} | {f('legacy')} | {f('numpy')} | {f('euler')} | {f('rk4')} | "
              f"{e / npy:.2f} | {leg / e:.1f} | {T_FINAL / e:.0f} | "
              f"{e / STEPS / n * 1e9:.0f} |")
    # per-step overhead of a two-block diagram at N = 1
    one_av = time_it(avblocks_run("euler"), 1, STEPS, 3) / STEPS
    one_np = time_it(plain_numpy, 1, STEPS, 3) / STEPS
    d = av.Diagram()
    f = d.add(av.vehicles.Unicycle(pose0=np.zeros((1, 3))), name="f")
    c = d.add(av.blocks.Constant(np.array([[1.0, 0.1]])), name="c")
    d.connect(c.y, f.cmd)
    t0 = CLOCK()
    av.simulate(d, T_FINAL, dt=DT, solver="euler", log=[f.pose], progress=False)
    trivial = (CLOCK() - t0) / STEPS
    print(f"\nN = 1, Euler: avblocks {one_av * 1e6:.1f} us/step, plain NumPy "
          f"{one_np * 1e6:.1f} us/step, framework overhead {(one_av - one_np) * 1e6:.1f} "
          f"us/step; Constant + Unicycle diagram {trivial * 1e6:.1f} us/step")
    labels = {"legacy": "Python loop over agents", "numpy": "plain NumPy",
              "euler": "avblocks (Euler)", "rk4": "avblocks (RK4)"}
    _plot(ns, [([rows[(n, kind)][0] for n in ns], style, labels[kind])
               for kind, style in (("legacy", "o-"), ("numpy", "s-"), ("euler", "^-"),
                                   ("rk4", "v-"))],
          "Go-to-goal unicycles, dt = 10 ms (cf. AVLib Fig. 3)", args.out)


def _plot(ns, curves, title, out):
    """Log-log wall time for 30 s simulated against N, one line per
    ``(times, style, label)``, with the real-time line; saved to ``out``."""
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return
    fig, ax = plt.subplots(figsize=(6, 4.2))
    for times, style, label in curves:
        ax.loglog(ns, times, style, label=label)
    ax.axhline(T_FINAL, color="k", lw=0.8, ls="--", label="real time (30 s)")
    ax.set_xlabel("number of unicycles N")
    ax.set_ylabel("wall time for 30 s simulated [s]")
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    print(f"plot: {out}")


if __name__ == "__main__":
    main()
