"""Interacting swarms: Olfati-Saber flocking on the NumPy engine, compiled
(JAX) and as a fused Numba cell-list loop; and the flocking ensemble.

Workload (the ``flocking`` scenario's maths at any N): N double
integrators on a jittered square lattice (spacing 5 m: constant density,
about 9 others within r), random velocities in [-2, 2]^2 m/s; every step
``environment.Neighbors`` lists the K = 12 nearest others within
r = 1.2 d = 8.4 m (held over the step), ``controllers.Flocking``
(Algorithm 1 + gamma term towards a target moving from the lattice's
centre) gives the accelerations; RK4, dt = 0.02 s. The agents are stored
in the lattice's order (row by row), nearly the search's cell order. On
the 2-core CPU (compiled, float64) a random order took 1.49 s a step at
N = 10^6 against 0.71 s in the search's cell order (0.74 s in the
lattice's), and was 5-15 % slower at N = 10^5 (run-to-run spread about
15 %). Columns, seconds per
step (median over the rounds; each (column, N) runs in a fresh process, the
columns alternate within a round, so a shared machine disturbs them alike):

  numpy   avblocks.simulate(..., backend="numpy")
  jax     avblocks.compile(...) then runner(), second call (compile excluded)
  numba   a fused single-threaded Numba loop of the same maths (cell list of
          side r, K nearest by insertion, RK4), written here; numba is a
          benchmark-only dependency. Checked against the NumPy engine at
          N = 100 (final positions to 1e-9 m) before timing.
  numba2  the same loop with its two loops over the agents run on two of
          Numba's threads (``prange``; not in the default columns): what
          two cores give the fused loop at best.

The last column, NumPy / Numba in process CPU time (both single-threaded),
is the ratio to trust on a shared machine, where other processes stretch
wall-clock times unevenly. Peak RSS (MiB) of each process is reported too: no (N, N) array anywhere,
so memory grows as O(N). Real-time factor = dt / (seconds per step).

    python benchmarks/interacting.py                  # N = 1e2 .. 1e5, plot
    python benchmarks/interacting.py --quick          # N = 1e2 .. 1e4
    python benchmarks/interacting.py --ensemble       # 256 flocking seeds
    python benchmarks/interacting.py --n 1000000 --engines jax,numba \
        --steps-scale 10 --rounds 1                   # on a GPU machine
    python benchmarks/interacting.py --alternate --rounds 7   # NumPy / Numba, one process
    python benchmarks/interacting.py --long --n 1000 10000    # 4 s runs: jax / Numba
    python benchmarks/interacting.py --long --n 100000 --numba2   # jax / two-thread Numba
    python benchmarks/interacting.py --float32 --n 1000       # float32 error, flocking
    python benchmarks/interacting.py --gpu --out-dir OUT --budget 420 --limit 200
                                                              # the GPU rows (one call)
    python benchmarks/interacting.py --gpu-parts --out-dir OUT   # a GPU step's parts

``--long`` (issue 32; one process, so the ratios share the machine's
state): the flock over ``--seconds`` (4) s contracts towards the target,
so the search's plan made at t0 overflows and grows. Rows: the Numba loop
(first call compiles it, then timed); the first ``simulate(backend="jax")``
of the diagram (plan, overflow, re-plan, compile twice); the second
``simulate`` of a *rebuilt* diagram of the same structure (the kept plan,
no trace, no compile); the compiled runner's second call; each ratio to
the Numba loop timed next to it (``--numba2``: the two-thread loop).

``--gpu`` writes ``gpu_issue47.md`` (and ``.json``) into ``--out-dir``: on
JAX's default device, the cases of ``GPU_CASES`` in order of need, each in
a child process with a time limit (``--limit``, 240 s; all within
``--budget``, 480 s, later cases skipped): flocking at N = 10^6 (RK4, dt
0.02, float64 then float32) and N = 10^7 (float32 then float64), each
from two runners of different step counts (10 and 50, 10 and 30), so a
row gives the time of a step and the fixed cost of a call (what a call
costs besides its steps), the plan's and the first call's seconds and the
peak device memory (10^6 also the search alone); a profile of one call at
10^7 in its own process (``cProfile`` of the host's Python and a
``jax.profiler`` trace, summarised: busy time and top spans of the host
and each device; the Perfetto file copied to ``--out-dir``); a check of
the device against the NumPy engine (N = 2000); N = 10^6 float32 with the
agents stored in a random order, then sorted by the search's cells (the
other rows store them in the lattice's order, row by row, nearly the
cells' already): what keeping agents in cell order between steps could
gain on that device, measured before it is built; sharded runs
(``shard="agents"``) on the machine's devices, then on its CPU split into
16 devices (1, 2, 4, 8, 16); and N = 10^6 over 4 s (the flock contracts,
one re-plan). The script sets ``AVBLOCKS_CACHE=off`` (unless set):
compiles and plans are timed as a first process sees them.
``--gpu-parts`` times a GPU step's parts alone (cell sort, k-nearest at two
chunk budgets, one law evaluation) at ``--n`` (10^6, 10^7).

On an accelerator the ``jax`` column runs there (JAX's default device,
printed first); ``numpy`` and ``numba`` always run on the host's CPU.
``--steps-scale`` multiplies the steps timed at each N (a GPU step at
N = 1e6 is short enough that 3 steps would mostly time the call itself).

``--ensemble``: the ``flocking`` scenario (50 agents, 30 s, dt 0.02, RK4) for
256 seeds in one ``runner.ensemble`` call (second call) against sequential
NumPy runs (``--numpy-runs`` of them timed, scaled to 256).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time

import numpy as np

# timings of compiles, plans and re-plans mean what they say only without the
# compiled engine's cache folder (programs and grown plans kept across
# processes, on by default): off here unless the caller says otherwise
os.environ.setdefault("AVBLOCKS_CACHE", "off")

D, R, K, DT = 7.0, 8.4, 12, 0.02
SPACING = 5.0
STEPS = {100: 200, 1000: 50, 10000: 12, 100000: 5, 1000000: 3}


def initial(n, seed=0):
    rng = np.random.default_rng(seed)
    m = int(np.ceil(np.sqrt(n)))
    g = np.stack(np.meshgrid(np.arange(m), np.arange(m), indexing="ij"), -1).reshape(-1, 2)
    p0 = (g[:n] + rng.uniform(-0.3, 0.3, (n, 2))) * SPACING
    v0 = rng.uniform(-2.0, 2.0, (n, 2))
    centre = p0.mean(axis=0)
    return p0, v0, centre


#: storage orders of the agents (``diagram(n, order)``): the lattice's own
#: (row by row: nearly the search's cell order), a random permutation, and
#: the search's own cell order (``utility.spatial.layout``)
ORDERS = ("lattice", "random", "cell")


def ordered(p0, v0, order):
    """``(p0, v0)`` with the agents stored in ``order`` (:data:`ORDERS`)."""
    if order == "random":
        perm = np.random.default_rng(1).permutation(len(p0))
    elif order == "cell":
        from avblocks.utility import spatial
        perm = spatial.layout(spatial.CellList(R), p0).order
    elif order == "lattice":
        return p0, v0
    else:
        raise ValueError(f"order must be one of {ORDERS}, got {order!r}")
    return p0[perm], v0[perm]


def diagram(n, order="lattice"):
    import avblocks as av
    p0, v0, centre = initial(n)
    p0, v0 = ordered(p0, v0, order)
    dg = av.Diagram("flocking-bench")
    flock = dg.add(av.vehicles.DoubleIntegrator(p0, velocity0=v0), name="flock")
    nb = dg.add(av.environment.Neighbors(n, K, radius=R, input="position", period=DT),
                name="neighbors")
    law = dg.add(av.controllers.Flocking(n, D, r=R, gamma=True, target=centre,
                                         target_velocity=np.array([2.0, 1.0])),
                 name="law")
    dg.connect(flock.position, nb.position)
    dg.connect(flock.position, law.position)
    dg.connect(flock.velocity, law.velocity)
    dg.connect(nb.neighbors, law.neighbors)
    dg.connect(law.accel, flock.accel)
    return dg


# --------------------------------------------------------------- Numba twin
def numba_kernels(parallel=False):
    """The fused loop; ``parallel``: its two loops over the agents as
    ``prange`` (Numba's threads; the ``numba2`` column runs it on two)."""
    import numba as nb
    jit = nb.njit(cache=not parallel, parallel=parallel)

    @jit
    def neighbours(q, k, r):
        n = q.shape[0]
        lo0, lo1 = q[:, 0].min(), q[:, 1].min()
        nx = int((q[:, 0].max() - lo0) / r) + 1
        ny = int((q[:, 1].max() - lo1) / r) + 1
        cell = np.empty(n, np.int64)
        count = np.zeros(nx * ny + 1, np.int64)
        for i in range(n):
            c = int((q[i, 0] - lo0) / r) * ny + int((q[i, 1] - lo1) / r)
            cell[i] = c
            count[c + 1] += 1
        for c in range(nx * ny):
            count[c + 1] += count[c]
        order = np.empty(n, np.int64)
        fill = count[:-1].copy()
        for i in range(n):
            order[fill[cell[i]]] = i
            fill[cell[i]] += 1
        idx = -np.ones((n, k), np.int64)
        rows = np.empty((n if parallel else 1, k))   # a row per thread's agent
        r2 = r * r
        for i in nb.prange(n):
            best = rows[i if parallel else 0]
            m = 0
            cx = int((q[i, 0] - lo0) / r)
            cy = int((q[i, 1] - lo1) / r)
            for ax in range(max(cx - 1, 0), min(cx + 2, nx)):
                for ay in range(max(cy - 1, 0), min(cy + 2, ny)):
                    c = ax * ny + ay
                    for s in range(count[c], count[c + 1]):
                        j = order[s]
                        if j == i:
                            continue
                        dx = q[j, 0] - q[i, 0]
                        dy = q[j, 1] - q[i, 1]
                        dd = dx * dx + dy * dy
                        if dd > r2:
                            continue
                        if m == k and (dd > best[k - 1] or (dd == best[k - 1]
                                                             and j > idx[i, k - 1])):
                            continue
                        p = m if m < k else k - 1
                        while p > 0 and (best[p - 1] > dd or (best[p - 1] == dd
                                                              and idx[i, p - 1] > j)):
                            if p < k:
                                best[p] = best[p - 1]
                                idx[i, p] = idx[i, p - 1]
                            p -= 1
                        best[p] = dd
                        idx[i, p] = j
                        if m < k:
                            m += 1
        return idx

    @jit
    def accel(q, p, idx, t, target, tvel, out):
        eps, a, b, h, c1, c2, c1g, c2g = 0.1, 5.0, 5.0, 0.2, 1.0, 1.0, 0.2, 0.4
        r_a = (np.sqrt(1.0 + eps * R * R) - 1.0) / eps
        d_a = (np.sqrt(1.0 + eps * D * D) - 1.0) / eps
        c = abs(a - b) / np.sqrt(4.0 * a * b)
        for i in nb.prange(q.shape[0]):
            ax = 0.0
            ay = 0.0
            for s in range(idx.shape[1]):
                j = idx[i, s]
                if j < 0:
                    continue
                dx = q[j, 0] - q[i, 0]
                dy = q[j, 1] - q[i, 1]
                root = np.sqrt(1.0 + eps * (dx * dx + dy * dy))
                sn = (root - 1.0) / eps
                x = sn / r_a
                if x < h:
                    rho = 1.0
                elif x <= 1.0:
                    rho = 0.5 * (1.0 + np.cos(np.pi * (x - h) / (1.0 - h)))
                else:
                    rho = 0.0
                z = sn - d_a + c
                phi = 0.5 * ((a + b) * z / np.sqrt(1.0 + z * z) + (a - b))
                wq = rho * phi / root
                ax += c1 * wq * dx + c2 * rho * (p[j, 0] - p[i, 0])
                ay += c1 * wq * dy + c2 * rho * (p[j, 1] - p[i, 1])
            out[i, 0] = ax - c1g * (q[i, 0] - target[0] - tvel[0] * t) \
                - c2g * (p[i, 0] - tvel[0])
            out[i, 1] = ay - c1g * (q[i, 1] - target[1] - tvel[1] * t) \
                - c2g * (p[i, 1] - tvel[1])

    @jit
    def run(q, p, steps, dt, target, tvel):
        n = q.shape[0]
        k1 = np.empty((n, 2))
        k2 = np.empty((n, 2))
        k3 = np.empty((n, 2))
        k4 = np.empty((n, 2))
        t = 0.0
        for _ in range(steps):
            idx = neighbours(q, K, R)
            accel(q, p, idx, t, target, tvel, k1)
            q2 = q + 0.5 * dt * p
            p2 = p + 0.5 * dt * k1
            accel(q2, p2, idx, t + 0.5 * dt, target, tvel, k2)
            q3 = q + 0.5 * dt * p2
            p3 = p + 0.5 * dt * k2
            accel(q3, p3, idx, t + 0.5 * dt, target, tvel, k3)
            q4 = q + dt * p3
            p4 = p + dt * k3
            accel(q4, p4, idx, t + dt, target, tvel, k4)
            q = q + dt / 6.0 * (p + 2.0 * p2 + 2.0 * p3 + p4)
            p = p + dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
            t += dt
        return q, p

    return run


def one(engine, n, steps):
    """Seconds per step of one column at one N (run in its own process)."""
    t_final = steps * DT
    if engine in ("numba", "numba2"):
        run = numba_kernels(parallel=engine == "numba2")
        if engine == "numba2":
            import numba as nb
            nb.set_num_threads(min(2, nb.config.NUMBA_NUM_THREADS))
        p0, v0, centre = initial(n)
        tv = np.array([2.0, 1.0])
        run(p0, v0, 1, DT, centre, tv)                      # compile
        t, c = time.perf_counter(), time.process_time()
        run(p0, v0, steps, DT, centre, tv)
        wall, cpu = time.perf_counter() - t, time.process_time() - c
    else:
        import avblocks as av
        dg = diagram(n)
        if engine == "numpy":
            t, c = time.perf_counter(), time.process_time()
            av.simulate(dg, t_final, dt=DT, log=["flock.position"], log_every=steps,
                        progress=False)
            wall, cpu = time.perf_counter() - t, time.process_time() - c
        else:
            runner = av.compile(dg, t_final, dt=DT, log=["flock.position"],
                                log_every=steps)
            runner()
            t, c = time.perf_counter(), time.process_time()
            runner()
            wall, cpu = time.perf_counter() - t, time.process_time() - c
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    return {"engine": engine, "n": n, "steps": steps, "s_per_step": wall / steps,
            "cpu_per_step": cpu / steps, "rss_mib": rss}


def check_numba(n=100, steps=100):
    """Final positions of the Numba twin against the NumPy engine."""
    import avblocks as av
    run = numba_kernels()
    p0, v0, centre = initial(n)
    q, _ = run(p0, v0, steps, DT, centre, np.array([2.0, 1.0]))
    res = av.simulate(diagram(n), steps * DT, dt=DT, log=["flock.position"],
                      log_every=steps, progress=False)
    return float(np.abs(np.asarray(res["flock.position"])[-1] - q).max())


def alternate(n, steps, rounds):
    """NumPy engine / Numba loop in one process: the two runs alternate,
    ``rounds`` times; the median of the per-round ratios of process CPU
    time (and of wall time) -- what to compare on a shared machine."""
    import avblocks as av
    run = numba_kernels()
    p0, v0, centre = initial(n)
    tv = np.array([2.0, 1.0])
    run(p0, v0, 1, DT, centre, tv)
    av.simulate(diagram(n), 2 * DT, dt=DT, log=["flock.position"], log_every=2,
                progress=False)
    cpu, wall = [], []
    for _ in range(rounds):
        dg = diagram(n)
        c, t = time.process_time(), time.perf_counter()
        av.simulate(dg, steps * DT, dt=DT, log=["flock.position"], log_every=steps,
                    progress=False)
        c1, t1 = time.process_time() - c, time.perf_counter() - t
        c, t = time.process_time(), time.perf_counter()
        run(p0, v0, steps, DT, centre, tv)
        cpu.append(c1 / (time.process_time() - c))
        wall.append(t1 / (time.perf_counter() - t))
    print(f"N = {n}: NumPy / Numba in one process, {rounds} rounds of {steps} steps: "
          f"CPU time {np.median(cpu):.2f} (rounds {np.round(cpu, 2).tolist()}), "
          f"wall {np.median(wall):.2f}")


def child(engine, n, steps):
    env = dict(os.environ)
    out = subprocess.run([sys.executable, __file__, "--one", engine, str(n), str(steps)],
                         capture_output=True, text=True, env=env, timeout=1800)
    if out.returncode:
        return {"engine": engine, "n": n, "error": out.stderr.strip().splitlines()[-1:]}
    return json.loads(out.stdout.strip().splitlines()[-1])


def scaling(ns, engines, rounds, plot, scale=1.0):
    if "jax" in engines:
        out = subprocess.run([sys.executable, "-c", "import jax; print(jax.devices()[0])"],
                             capture_output=True, text=True)
        print(f"jax default device: {out.stdout.strip() or out.stderr.strip()[-200:]}")
    err = check_numba()
    print(f"numba twin vs NumPy engine, N = 100, 100 steps: max |dq| = {err:.2e} m")
    assert err < 1e-9, err
    rows = {}
    cpu_ratio = "numpy" in engines and "numba" in engines
    for _ in range(rounds):
        for n in ns:
            for e in engines:
                r = child(e, n, max(1, round(STEPS.get(n, 3) * scale)))
                rows.setdefault((e, n), []).append(r)
    print(f"\n{'N':>8} " + " ".join(f"{e + ' s/step':>14}" for e in engines)
          + "   " + " ".join(f"{e + '/numba':>12}" for e in engines if e != "numba")
          + "   " + " ".join(f"{e + ' MiB':>10}" for e in engines) + "   RTF(jax)"
          + ("   numpy/numba CPU" if cpu_ratio else ""))
    table = {}
    for n in ns:
        med = {}
        for e in engines:
            good = [r for r in rows[(e, n)] if "error" not in r]
            if not good:
                print(f"{e} at N={n} failed: {rows[(e, n)][0].get('error')}")
                med[e] = (float("nan"), float("nan"), float("nan"))
                continue
            med[e] = (float(np.median([r["s_per_step"] for r in good])),
                      float(np.median([r["rss_mib"] for r in good])),
                      float(np.median([r["cpu_per_step"] for r in good])))
        table[n] = med
        nbt = med.get("numba", (np.nan,))[0]
        rtf = DT / med["jax"][0] if "jax" in med else float("nan")
        print(f"{n:>8} " + " ".join(f"{med[e][0]:>14.3e}" for e in engines)
              + "   " + " ".join(f"{med[e][0] / nbt:>12.2f}" for e in engines if e != "numba")
              + "   " + " ".join(f"{med[e][1]:>10.0f}" for e in engines) + f"   {rtf:8.2f}"
              + (f"   {med['numpy'][2] / med['numba'][2]:17.2f}" if cpu_ratio else ""))
    if plot:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.2))
        for e, style in zip(engines, ("o-", "s-", "^-")):
            a.loglog(ns, [table[n][e][0] for n in ns], style, label=e)
            b.loglog(ns, [table[n][e][1] for n in ns], style, label=e)
        a.set_xlabel("agents N")
        a.set_ylabel("seconds per RK4 step (median)")
        a.set_title(f"flocking, K = {K} within r, dt = {DT} s")
        b.set_xlabel("agents N")
        b.set_ylabel("peak RSS of the process [MiB]")
        b.set_title("memory (no (N, N) array: O(N))")
        for ax in (a, b):
            ax.grid(True, which="both", alpha=0.3)
            ax.legend()
        fig.tight_layout()
        fig.savefig(plot, dpi=100)
        print(f"wrote {plot}")
    return table


def ensemble(runs, numpy_runs):
    """The ensemble (second and later calls) and ``numpy_runs`` NumPy runs,
    alternating (ensemble call, NumPy run of seed s, ...): the ratio of the
    medians, NumPy per run x ``runs`` / ensemble."""
    import avblocks as av
    from avblocks.scenarios import flocking as F
    dg, sim = F.make_diagram(agents=50, t_final=30.0)
    settings = {k: v for k, v in sim.items() if k != "seed"}
    seeds = list(range(runs))
    x0 = F.ensemble_x0(seeds)
    runner = av.compile(dg, **settings)
    t = time.perf_counter()
    runner.ensemble(seeds=seeds, x0=x0)
    first = time.perf_counter() - t
    te, ts, err = [], [], 0.0
    for s in range(numpy_runs):
        t = time.perf_counter()
        ens = runner.ensemble(seeds=seeds, x0=x0)
        te.append(time.perf_counter() - t)
        d, sm = F.make_diagram(agents=50, t_final=30.0, seed=s)
        t = time.perf_counter()
        ref = av.simulate(d, progress=False, **sm)
        ts.append(time.perf_counter() - t)
        err = max(err, float(np.abs(np.asarray(ref["flock.position"])
                                    - ens["flock.position"][s]).max()))
    second, one = float(np.median(te)), float(np.median(ts))
    seq = one * runs
    print(f"flocking, 50 agents, 30 s, {runs} seeds: ensemble {second:.2f} s (median of "
          f"{numpy_runs} calls, chunks of {ens.meta['chunk_size']}; first call {first:.2f} s "
          f"with compile); sequential NumPy {one:.3f} s per run x {runs} = {seq:.1f} s "
          f"(median of {numpy_runs} runs, alternating); speed-up {seq / second:.1f}x; "
          f"runs 0..{numpy_runs - 1} agree to {err:.1e} m; load {os.getloadavg()[0]:.1f}")


def _timed(fn):
    t = time.perf_counter()
    out = fn()
    return time.perf_counter() - t, out


def long_runs(ns, seconds, rounds, two_threads=False):
    """Issue 32's long rows (see the module docstring), one process per N."""
    import warnings

    import avblocks as av
    from avblocks.core.compiled import cache_info
    steps = int(round(seconds / DT))
    kind = "numba2" if two_threads else "numba"
    run = numba_kernels(parallel=two_threads)
    if two_threads:
        import numba as nb
        nb.set_num_threads(min(2, nb.config.NUMBA_NUM_THREADS))
    tv = np.array([2.0, 1.0])
    kw = dict(dt=DT, log=["flock.position"], log_every=steps)
    print(f"flocking over {seconds:g} s ({steps} RK4 steps of {DT} s), K = {K}; "
          f"load {os.getloadavg()[0]:.1f}; jax device "
          f"{__import__('jax').devices()[0].platform}")
    print(f"\n| N | {kind} s | 1st simulate s | 2nd simulate (rebuilt) s | / {kind} | "
          f"runner s | / {kind} | plan (capacity, hits) | re-plans 1st / 2nd | "
          f"traces, XLA compiles in 2nd |")
    print("|---:|---:|---:|---:|---:|---:|---:|---|---|---|")
    for n in ns:
        p0, v0, centre = initial(n)
        run(p0, v0, 1, DT, centre, tv)                      # compile the loop

        def loop(p0=p0, v0=v0, centre=centre):
            return _timed(lambda: run(p0, v0, steps, DT, centre, tv))[0]

        def sim(n=n):
            with warnings.catch_warnings(record=True) as w:
                warnings.simplefilter("always")
                el, res = _timed(lambda: av.simulate(diagram(n), seconds, backend="jax",
                                                     **kw))
            return el, res, sum("re-planned" in str(x.message) for x in w)
        first, _, rp1 = sim()
        c0 = cache_info()
        sims, loops, runs, rp2 = [], [], [], 0
        for _ in range(rounds):
            el, res, r = sim()
            rp2 += r
            sims.append(el)
            loops.append(loop())
        c1 = cache_info()
        runner = av.compile(diagram(n), seconds, **kw)
        runner()
        rl = []
        for _ in range(rounds):
            runs.append(_timed(runner)[0])
            rl.append(loop())
        plan = next(iter(runner.plans.values()))
        sim_r = float(np.median(np.divide(sims, loops)))
        run_r = float(np.median(np.divide(runs, rl)))
        print(f"| {n} | {np.median(loops + rl):.3f} | {first:.2f} | {np.median(sims):.3f} | "
              f"{sim_r:.2f} | {np.median(runs):.3f} | {run_r:.2f} | "
              f"{plan.capacity}, {plan.hits} | {rp1} / {rp2} | "
              f"{c1['traces'] - c0['traces']}, {c1['xla_compiled'] - c0['xla_compiled']} |",
              flush=True)


def float32_error(n, seconds):
    """Positions of the flock after ``seconds`` in float32 against float64
    (both compiled, same diagram and initial state)."""
    import avblocks as av
    steps = int(round(seconds / DT))
    out = {}
    for dt in ("float64", "float32"):
        res = av.simulate(diagram(n), seconds, dt=DT, backend="jax", dtype=dt,
                          log=["flock.position", "flock.velocity"], log_every=steps)
        out[dt] = (np.asarray(res["flock.position"][-1], float),
                   np.asarray(res["flock.velocity"][-1], float))
    dp = np.linalg.norm(out["float32"][0] - out["float64"][0], axis=1)
    dv = np.linalg.norm(out["float32"][1] - out["float64"][1], axis=1)
    print(f"flocking N = {n}, {seconds:g} s ({steps} RK4 steps), float32 vs float64: "
          f"position max {dp.max():.3g} m, median {np.median(dp):.3g} m; velocity max "
          f"{dv.max():.3g} m/s, median {np.median(dv):.3g} m/s; device "
          f"{__import__('jax').devices()[0].platform}")


def _timed_calls(runner, calls):
    walls = []
    res = None
    for _ in range(calls):
        t = time.perf_counter()
        res = runner()
        walls.append(time.perf_counter() - t)
    return min(walls), walls, res


def _gpu_runner_row(n, dtype, steps, calls=3, order="lattice"):
    """One (N, dtype) row on JAX's default device, from two runners of
    ``steps = (s1, s2)`` steps (each planned and compiled, then the best of
    ``calls`` calls after the first): the time of a step, ``(T2 - T1) / (s2
    - s1)``, and a call's fixed cost, ``T1 - s1 * step`` (what a call costs
    besides its steps: transfers between host and device, the host's work
    on the results). ``plan_s``: ``avblocks.compile`` of the first runner
    (the plan: the points the search needs at t0, counted on the host);
    ``first_call_s``: its first call (XLA compile, any re-plan, the run);
    ``peak_device_mib``: JAX's ``peak_bytes_in_use`` after both. ``order``:
    how the agents are stored (:data:`ORDERS`)."""
    import jax

    import avblocks as av
    s1, s2 = steps if len(steps) > 1 else (steps[0], None)
    t = time.perf_counter()
    runner = av.compile(diagram(n, order), s1 * DT, dt=DT, log=["flock.position"],
                        log_every=s1, dtype=dtype)
    plan_s = time.perf_counter() - t
    t = time.perf_counter()
    runner()
    first = time.perf_counter() - t
    t1, walls1, res = _timed_calls(runner, calls)
    row = {"n": n, "dtype": dtype, "order": order, "steps": [s1] + ([s2] if s2 else []),
           "device": str(jax.devices()[0]), "plan_s": plan_s, "first_call_s": first,
           "ms_per_call": [round(1e3 * w, 2) for w in walls1],
           "ms_per_step": 1e3 * t1 / s1, "plan": str(next(iter(runner.plans.values())))}
    if s2:
        r2 = av.compile(diagram(n, order), s2 * DT, dt=DT, log=["flock.position"],
                        log_every=s2, dtype=dtype)
        r2()
        t2, walls2, res = _timed_calls(r2, calls)
        step = (t2 - t1) / (s2 - s1)
        row.update(ms_per_step=1e3 * step, fixed_ms=1e3 * (t1 - s1 * step),
                   ms_per_call=row["ms_per_call"] + [round(1e3 * w, 2) for w in walls2])
    row["realtime_factor"] = DT / (row["ms_per_step"] / 1e3)
    stats = jax.devices()[0].memory_stats() or {}
    row["peak_device_mib"] = stats.get("peak_bytes_in_use", 0) / 2**20
    pos = np.asarray(res["flock.position"][-1], float)
    row["finite"] = bool(np.isfinite(pos).all())
    return row, runner


def _gpu_search_ms(runner, n, calls=10):
    """The k-nearest search alone (``spatial.nearest`` with the run's plan,
    jitted, float64, on the initial lattice): ms per call, best of
    ``calls`` -- how much of a step the search is."""
    import jax
    import jax.numpy as jnp

    from avblocks.utility import spatial as sp
    jax.config.update("jax_enable_x64", True)
    plan = next(iter(runner.plans.values()))
    f = jax.jit(lambda p: sp.nearest(plan, p, R, K, None, jnp)[:2])
    p = jnp.asarray(initial(n)[0])
    jax.block_until_ready(f(p))
    best = np.inf
    for _ in range(calls):
        t = time.perf_counter()
        jax.block_until_ready(f(p))
        best = min(best, time.perf_counter() - t)
    return 1e3 * best


def _gpu_check(n=2000, steps=10):
    """Correctness on the device: the compiled run (float64 and float32)
    against the NumPy engine on the host, final positions."""
    import avblocks as av
    ref = av.simulate(diagram(n), steps * DT, dt=DT, backend="numpy",
                      log=["flock.position"], log_every=steps)
    want = np.asarray(ref["flock.position"][-1], float)
    out = {"n": n, "steps": steps, "case": "check"}
    for dt in ("float64", "float32"):
        res = av.simulate(diagram(n), steps * DT, dt=DT, backend="jax", dtype=dt,
                          log=["flock.position"], log_every=steps)
        got = np.asarray(res["flock.position"][-1], float)
        out[f"max_dp_{dt}_m"] = float(np.abs(got - want).max())
    return out


def trace_summary(path, top=12):
    """What a Perfetto trace (``jax.profiler.trace(...,
    create_perfetto_trace=True)``, gzipped JSON) spent: per process (host,
    each device) the time its threads were busy (union of spans) and the
    span names that took the most (Python frames start with ``$``: their
    time includes what they called)."""
    import collections
    import gzip
    with gzip.open(path, "rt") as f:
        ev = json.load(f)["traceEvents"]
    pname = {e["pid"]: e["args"]["name"] for e in ev
             if e.get("ph") == "M" and e.get("name") == "process_name"}
    spans = collections.defaultdict(list)
    names = collections.defaultdict(collections.Counter)
    first, last = np.inf, -np.inf
    for e in ev:
        if e.get("ph") != "X":
            continue
        if e["name"].startswith(("$profiler.py", "$contextlib.py")):
            continue                            # the profiler stopping itself
        s, d = float(e["ts"]), float(e.get("dur", 0.0))
        first, last = min(first, s), max(last, s + d)
        spans[(e["pid"], e.get("tid"))].append((s, s + d))
        names[e["pid"]][e["name"]] += d
    out = {"span_ms": (last - first) / 1e3, "processes": {}}
    for pid, counter in names.items():
        busy = 0.0
        for (p, _), iv in spans.items():
            if p != pid:
                continue
            iv.sort()
            end = -np.inf
            for a, b in iv:                    # union of the thread's spans
                if b > end:
                    busy += b - max(a, end)
                    end = b
        out["processes"][pname.get(pid, str(pid))] = {
            "busy_ms_all_threads": busy / 1e3,
            "top_ms": [(k[:90], round(v / 1e3, 2)) for k, v in counter.most_common(top)]}
    return out


def _gpu_profile(n, dtype, steps, out_dir):
    """Where a call's fixed cost goes (its own process: a trace must not
    hold up the timed rows): one runner of ``steps`` steps at ``n`` agents,
    compiled and called once, then one call under ``cProfile`` (the host's
    Python work, top functions) and one under ``jax.profiler.trace``
    (Perfetto JSON: the host's and the device's busy time and top spans,
    summarised here; the trace file is copied to ``out_dir`` when small)."""
    import cProfile
    import glob
    import io
    import pstats
    import shutil
    import tempfile

    import jax

    import avblocks as av
    runner = av.compile(diagram(n), steps * DT, dt=DT, log=["flock.position"],
                        log_every=steps, dtype=dtype)
    runner()
    t = time.perf_counter()
    runner()
    wall = time.perf_counter() - t
    prof = cProfile.Profile()
    prof.enable()
    runner()
    prof.disable()
    text = io.StringIO()
    pstats.Stats(prof, stream=text).sort_stats("cumulative").print_stats(25)
    lines = [x for x in text.getvalue().splitlines() if "/" in x or "{" in x][:25]
    tmp = tempfile.mkdtemp(prefix="avblocks-trace-")
    with jax.profiler.trace(tmp, create_perfetto_trace=True):
        t = time.perf_counter()
        runner()
        traced_wall = time.perf_counter() - t
    found = glob.glob(os.path.join(tmp, "**", "perfetto_trace.json.gz"), recursive=True)
    summary = trace_summary(found[0]) if found else {"error": "no perfetto trace written"}
    if found and os.path.getsize(found[0]) < 15 * 2**20:
        shutil.copy(found[0], os.path.join(out_dir, f"trace_{n}_{dtype}.json.gz"))
    return {"n": n, "dtype": dtype, "steps": steps, "case": "profile",
            "call_s": wall, "traced_call_s": traced_wall, "host_python_top": lines,
            "trace": summary}


def _sharded_row(n, devices, steps):
    """A sharded run (``shard="agents"``) of the flock at ``n`` agents on
    ``devices`` devices of JAX's default backend, best of 3 calls."""
    import jax

    import avblocks as av
    runner = av.compile(diagram(n), steps * DT, dt=DT, log=["flock.position"],
                        log_every=steps, devices=devices,
                        shard="agents" if devices > 1 else "auto")
    runner()
    best, walls, _ = _timed_calls(runner, 3)
    return {"n": n, "devices": devices, "steps": steps, "case": "devices",
            "platform": jax.devices()[0].platform, "ms_per_step": 1e3 * best / steps,
            "ms_per_call": [round(1e3 * w, 2) for w in walls]}


def gpu_child(case, n, dtypes, steps, out_dir="."):
    """One GPU case in its own process: ``rows`` (one runner row per dtype,
    in order), ``search`` (rows, then the search alone with the
    last row's plan), ``check`` (device against the NumPy engine),
    ``profile`` (a traced call), ``order`` (float32 rows; ``dtypes`` holds
    the agents' storage orders) or ``devices`` (sharded runs; ``dtypes``
    holds the device counts)."""
    import jax
    print(f"# device {jax.devices()[0]} (JAX {jax.__version__})", file=sys.stderr, flush=True)
    if case == "check":
        return [_gpu_check(n, steps[0])]
    if case == "profile":
        return [_gpu_profile(n, dtypes[0], steps[0], out_dir)]
    if case == "order":                 # float32 rows, one per storage order
        rows = []
        for o in dtypes:
            r, _ = _gpu_runner_row(n, "float32", steps, order=o)
            print(json.dumps(r), file=sys.stderr, flush=True)
            rows.append(r)
        return rows
    if case == "devices":
        rows = []
        for d in dtypes:
            r = _sharded_row(n, int(d), steps[0])
            print(json.dumps(r), file=sys.stderr, flush=True)
            rows.append(r)
        return rows
    rows, runner = [], None
    for dt in dtypes:
        r, runner = _gpu_runner_row(n, dt, steps)
        print(json.dumps(r), file=sys.stderr, flush=True)   # kept if a later row dies
        rows.append(r)
    if case == "search":
        rows[0]["search_ms"] = _gpu_search_ms(runner, n)
    return rows


#: the GPU cases, most wanted first: (case, N, dtypes or device counts,
#: steps, environment). ``devices`` on the machine's GPU(s), then on its
#: CPU split into 16 devices (XLA's forced host devices): how a sharded
#: step scales with devices
GPU_CASES = [("search", 10**6, ("float64", "float32"), (10, 50), {}),
             ("rows", 10**7, ("float32", "float64"), (10, 30), {}),
             ("profile", 10**7, ("float32",), (10,), {}),
             ("check", 2000, (), (10,), {}),
             ("order", 10**6, ("random", "cell"), (10, 50), {}),
             ("devices", 2**20, ("ALL",), (20,), {}),
             ("devices", 2**16, ("1", "2", "4", "8", "16"), (10,),
              {"JAX_PLATFORMS": "cpu", "JAX_NUM_CPU_DEVICES": "16",
               "XLA_FLAGS": "--xla_force_host_platform_device_count=16"}),
             ("rows", 10**6, ("float64",), (200,), {})]          # 4 s: the flock contracts


def gpu(out_dir, limit, budget):
    """The GPU rows of issue 47, each case in a child process with a time
    limit (``limit``, and what is left of ``budget`` seconds for all);
    tables written to ``out_dir`` after every case."""
    rows = []
    end = time.perf_counter() + budget
    os.makedirs(out_dir, exist_ok=True)
    for case, n, dts, steps, env in GPU_CASES:
        left = min(limit, end - time.perf_counter())
        if left < 20:
            rows.append({"n": n, "case": case, "error": "skipped: out of time"})
            continue
        if "ALL" in dts:                        # every device of the default backend
            out = subprocess.run([sys.executable, "-c",
                                  "import jax; print(len(jax.devices()))"],
                                 capture_output=True, text=True)
            count = int(out.stdout.strip() or 1)
            dts = tuple(str(d) for d in (1, 2, 4, 8) if d <= count)
        t = time.perf_counter()
        try:
            out = subprocess.run([sys.executable, __file__, "--gpu-one", case, str(n),
                                  ",".join(dts) or "-", ",".join(map(str, steps)),
                                  "--out-dir", out_dir],
                                 capture_output=True, text=True, timeout=left,
                                 env={**os.environ, **env})
            got = json.loads(out.stdout.strip().splitlines()[-1]) if out.returncode == 0 \
                else None
            err = out.stderr
        except subprocess.TimeoutExpired as e:
            got, err = None, (e.stderr.decode() if isinstance(e.stderr, bytes)
                              else e.stderr or "") + f"\nover {left:.0f} s"
        sys.stderr.write(err[-3000:])
        if got is None:
            # rows a child finished before it failed are on its stderr
            done = [json.loads(x) for x in err.splitlines() if x.startswith('{"n"')]
            got = done + [{"n": n, "case": case, "dtype": "-",
                           "error": err.strip()[-400:]}]
        for r in got:
            r.setdefault("case", case)
            r["case_s"] = time.perf_counter() - t
        rows.extend(got)
        for r in got:
            print(json.dumps(r), flush=True)
        _gpu_tables(rows, out_dir)
    _gpu_tables(rows, out_dir)


def _gpu_tables(rows, out_dir):
    with open(os.path.join(out_dir, "gpu_issue47.json"), "w") as f:
        json.dump(rows, f, indent=1)
    lines = ["| N | dtype | steps | ms per step | fixed ms per call | real-time factor | "
             "plan s | first call s | peak device MiB | search alone ms | plan |",
             "|---:|---|---|---:|---:|---:|---:|---:|---:|---:|---|"]
    extra = []
    for r in rows:
        if "error" in r:
            lines.append(f"| {r['n']} | {r.get('dtype', '-')} | {r['case']} | failed: "
                         f"{r['error'][-120:]!r} ||||||||")
        elif r.get("case") == "check":
            extra.append(f"check, N = {r['n']}, {r['steps']} steps, device against the "
                         f"NumPy engine: max |dp| float64 {r['max_dp_float64_m']:.3g} m, "
                         f"float32 {r['max_dp_float32_m']:.3g} m")
        elif r.get("case") == "devices":
            extra.append(f"sharded (shard='agents'), N = {r['n']}, {r['devices']} "
                         f"{r['platform']} device(s): {r['ms_per_step']:.2f} ms per step "
                         f"(calls {r['ms_per_call']} ms, {r['steps']} steps)")
        elif r.get("case") == "profile":
            extra.append(f"profile, N = {r['n']} {r['dtype']}, {r['steps']} steps: call "
                         f"{r['call_s']:.3f} s (traced {r['traced_call_s']:.3f} s)\n"
                         + json.dumps(r["trace"], indent=1)
                         + "\nhost Python (cProfile, cumulative):\n"
                         + "\n".join(r["host_python_top"]))
        else:
            sm = f"{r['search_ms']:.2f}" if "search_ms" in r else ""
            fx = f"{r['fixed_ms']:.1f}" if "fixed_ms" in r else ""
            order = "" if r.get("order", "lattice") == "lattice" else f", {r['order']} order"
            lines.append(f"| {r['n']} | {r['dtype']}{order} | {r['steps']} | "
                         f"{r['ms_per_step']:.2f} | {fx} | {r['realtime_factor']:.2f} | "
                         f"{r['plan_s']:.1f} | {r['first_call_s']:.1f} | "
                         f"{r['peak_device_mib']:.0f} | {sm} | {r['plan']} |")
    dev = next((r["device"] for r in rows if "device" in r), "?")
    text = f"device {dev}; flocking, K = {K}, RK4, dt = {DT} s\n\n" + "\n".join(lines)
    text += "".join("\n\n" + x for x in extra)
    with open(os.path.join(out_dir, "gpu_issue47.md"), "w") as f:
        f.write(text + "\n")
    print(text, flush=True)


def _best_ms(f, *args, calls=10):
    import jax
    jax.block_until_ready(f(*args))
    best = np.inf
    for _ in range(calls):
        t = time.perf_counter()
        jax.block_until_ready(f(*args))
        best = min(best, time.perf_counter() - t)
    return 1e3 * best


def gpu_parts(out_dir, ns=(10**6, 10**7), chunk_bytes=(2**31, 2**33)):
    """Where a GPU step goes (float64, the initial lattice, each part
    jitted alone, best of 10): the cell sort (``layout``), the k-nearest
    search at each accelerator chunk budget (``ACCEL_CHUNK_BYTES``), and
    one evaluation of the flocking law on the found neighbours (a step
    evaluates it four times). Written to ``gpu_parts.md`` / ``.json``."""
    import jax
    import jax.numpy as jnp

    from avblocks.controllers.flocking import flocking_law
    from avblocks.utility import spatial as sp
    from avblocks.utility.spatial import queries
    from avblocks.utility.spatial.layout import layout
    jax.config.update("jax_enable_x64", True)
    plan = sp.CellList(R, capacity=50, hits=24)       # the runs' plan at t0
    rows = []
    for n in ns:
        p0, v0, _ = initial(n)
        p, v = jnp.asarray(p0), jnp.asarray(v0)
        r = {"n": n, "device": str(jax.devices()[0]),
             "layout_ms": _best_ms(jax.jit(lambda p: layout(plan, p, jnp).order), p)}
        for cb in chunk_bytes:
            queries.ACCEL_CHUNK_BYTES = cb
            f = jax.jit(lambda p: sp.nearest(plan, p, R, K, None, jnp)[:2])
            r[f"nearest_ms_chunk_{cb >> 20}MiB"] = _best_ms(f, p)
            r[f"rows_per_chunk_{cb >> 20}MiB"] = queries.traced_rows(plan.capacity)
        queries.ACCEL_CHUNK_BYTES = chunk_bytes[0]
        idx, dist = jax.jit(lambda p: sp.nearest(plan, p, R, K, None, jnp)[:2])(p)
        r["law_ms"] = _best_ms(jax.jit(lambda p, v, i: flocking_law(p, v, i, D, R, xp=jnp)),
                               p, v, idx)
        print(json.dumps(r), flush=True)
        rows.append(r)
    os.makedirs(out_dir, exist_ok=True)
    with open(os.path.join(out_dir, "gpu_parts.json"), "w") as f:
        json.dump(rows, f, indent=1)
    keys = [k for k in rows[0] if k not in ("n", "device")]
    text = "| N | " + " | ".join(keys) + " |\n|" + "---:|" * (len(keys) + 1) + "\n"
    for r in rows:
        text += f"| {r['n']} | " + " | ".join(f"{r[k]:.3g}" for k in keys) + " |\n"
    with open(os.path.join(out_dir, "gpu_parts.md"), "w") as f:
        f.write(f"device {rows[0]['device']}\n\n" + text)
    print(text, flush=True)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="N up to 1e4")
    ap.add_argument("--n", type=int, nargs="*", help="agent counts")
    ap.add_argument("--engines", default="numpy,jax,numba")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--out", default="docs/images/interacting.png")
    ap.add_argument("--ensemble", action="store_true")
    ap.add_argument("--runs", type=int, default=256)
    ap.add_argument("--numpy-runs", type=int, default=16, dest="numpy_runs")
    ap.add_argument("--steps-scale", type=float, default=1.0, dest="scale",
                    help="multiply the steps timed at each N")
    ap.add_argument("--alternate", action="store_true",
                    help="NumPy / Numba alternating in one process (--n, --rounds)")
    ap.add_argument("--long", action="store_true",
                    help="issue 32's long runs: 2nd simulate of a rebuilt diagram and "
                         "the runner against the Numba loop, one process per N")
    ap.add_argument("--seconds", type=float, default=4.0, help="--long: simulated time")
    ap.add_argument("--numba2", action="store_true",
                    help="--long: against the two-thread Numba loop")
    ap.add_argument("--float32", action="store_true",
                    help="float32 against float64 positions after --seconds (--n)")
    ap.add_argument("--gpu", action="store_true", help="the GPU rows, tables to --out-dir")
    ap.add_argument("--gpu-parts", action="store_true", dest="gpu_parts",
                    help="a GPU step's parts timed alone (--n), table to --out-dir")
    ap.add_argument("--out-dir", default=".", dest="out_dir")
    ap.add_argument("--limit", type=float, default=240.0, help="--gpu: seconds per case")
    ap.add_argument("--budget", type=float, default=480.0,
                    help="--gpu: seconds for all cases (later cases are skipped)")
    ap.add_argument("--one", nargs=3, metavar=("ENGINE", "N", "STEPS"),
                    help=argparse.SUPPRESS)
    ap.add_argument("--gpu-one", nargs=4, dest="gpu_one", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.gpu_one:
        case, n, dts, steps = a.gpu_one
        print(json.dumps(gpu_child(case, int(n), [d for d in dts.split(",") if d != "-"],
                                   [int(x) for x in steps.split(",")], a.out_dir)))
        return
    if a.gpu_parts:
        gpu_parts(a.out_dir, tuple(a.n or (10**6, 10**7)))
        return
    if a.gpu:
        gpu(a.out_dir, a.limit, a.budget)
        return
    if a.long:
        long_runs(a.n or [1000, 10000], a.seconds, a.rounds, a.numba2)
        return
    if a.float32:
        for n in a.n or [1000]:
            float32_error(n, a.seconds)
        return
    if a.one:
        print(json.dumps(one(a.one[0], int(a.one[1]), int(a.one[2]))))
        return
    if a.ensemble:
        ensemble(a.runs, a.numpy_runs)
        return
    if a.alternate:
        for n in a.n or [1000, 10000]:
            alternate(n, STEPS.get(n, 3) * (2 if n <= 1000 else 1), max(a.rounds, 5))
        return
    ns = a.n or ([100, 1000, 10000] + ([] if a.quick else [100000]))
    scaling(ns, a.engines.split(","), a.rounds, a.out, a.scale)


if __name__ == "__main__":
    main()
