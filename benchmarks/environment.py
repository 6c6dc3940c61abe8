"""Per-step cost of the environment blocks at N = 100, 1,000, 10,000 agents.

World: 200 random convex obstacles in a square whose side grows with N so
the agent density stays constant (one agent per 16 m^2); obstacle size
scales with the side. Each block's ``output`` is timed (median of repeats)
on random poses. Prints a markdown table; the last columns divide by
N log2 N to show the growth.

Run: ``python benchmarks/environment.py``

``--methods`` instead compares, for ``Collision`` and ``RangeSensor``, the
NumPy engine's default (the shapely method) with the traceable grid method
run by NumPy and jitted by JAX (CPU, float64; the agent search planned
from the positions, headroom 2): ``python benchmarks/environment.py --methods
[N ...]``.
"""

from __future__ import annotations

import math
import time

import numpy as np
import shapely

from avblocks.environment import (
    Collision,
    Disc,
    Neighbors,
    RangeSensor,
    Rectangle,
    World,
)


def make_world(side, gen, m=200):
    obs = [shapely.MultiPoint(c + gen.normal(0, 0.02 * side, (6, 2))).convex_hull
           for c in gen.uniform(0, side, (m, 2))]
    return World(obs, bounds=(0, 0, side, side), walls=True)


def timeit(fn, reps):
    fn()
    ts = []
    for _ in range(reps):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return 1e3 * float(np.median(ts))


def main():
    gen = np.random.default_rng(0)
    rows = []
    for n in (100, 1_000, 10_000):
        side = 4.0 * np.sqrt(n)
        w = make_world(side, gen)
        pose = np.c_[gen.uniform(0, side, (n, 2)), gen.uniform(-np.pi, np.pi, n)]
        u = {"pose": pose}
        blocks = {
            "Collision disc": Collision(w, n, footprint=Disc(0.3)),
            "Collision rect": Collision(w, n, footprint=Rectangle(0.6, 0.4)),
            "Neighbors r=8 k=8": Neighbors(n, 8, radius=8.0),
            "Neighbors fov": Neighbors(n, 8, radius=8.0, fov=np.pi),
            "RangeSensor 32 rays": RangeSensor(w, n, n_rays=32, max_range=8.0,
                                               agent_radius=0.3),
        }
        reps = 5 if n >= 10_000 else 20
        res = {}
        for name, b in blocks.items():
            x = b.initial_state()
            res[name] = timeit(lambda b=b, x=x, u=u: b.output(0.0, x, u, np), reps)
        rows.append((n, res))
    names = list(rows[0][1])
    print("| N | " + " | ".join(f"{k} [ms]" for k in names) + " |")
    print("|---:|" + "---:|" * len(names))
    for n, res in rows:
        print(f"| {n:,} | " + " | ".join(f"{res[k]:.2f}" for k in names) + " |")
    print()
    print("Per N log2 N [ns] (flat = N log N growth):")
    print()
    print("| N | " + " | ".join(names) + " |")
    print("|---:|" + "---:|" * len(names))
    for n, res in rows:
        nl = n * np.log2(n)
        print(f"| {n:,} | " + " | ".join(f"{1e6 * res[k] / nl:.0f}" for k in names) + " |")


def methods(ns):
    """Per-call ms: shapely (NumPy default) | grid in NumPy | grid jitted."""
    gen = np.random.default_rng(0)
    try:
        import jax
        import jax.numpy as jnp

        from avblocks.core.compiled._jax import x64
    except ImportError:                                   # pragma: no cover
        jax = None
    print("| N | block | shapely, NumPy [ms] | grid, NumPy [ms] | grid, jit CPU [ms] |")
    print("|---:|---|---:|---:|---:|")
    for n in ns:
        side = 4.0 * np.sqrt(n)
        w = make_world(side, gen)
        pose = np.c_[gen.uniform(0, side, (n, 2)), gen.uniform(-np.pi, np.pi, n)]
        u = {"pose": pose}
        reps = 3 if n >= 10_000 else 10
        makers = {
            "Collision disc": lambda m, w=w, n=n: Collision(
                w, n, footprint=Disc(0.3), method=m),
            "Collision rect": lambda m, w=w, n=n: Collision(
                w, n, footprint=Rectangle(0.6, 0.4), method=m),
            "RangeSensor 32 rays": lambda m, w=w, n=n: RangeSensor(
                w, n, n_rays=32, max_range=8.0, agent_radius=0.3, method=m),
        }
        for name, mk in makers.items():
            row = []
            for m in ("shapely", "grid"):
                b = mk(m)
                row.append(timeit(lambda b=b, u=u: b.output(0.0, {}, u, np), reps))
            if jax is not None:
                if b.search is not None and math.isfinite(b.search.reach):
                    b.search.plan(pose)         # capacity from these positions, as
                with x64(True):                 # the compiled engine plans it
                    f = jax.jit(lambda p, b=b: b.output(0.0, {}, {"pose": p}, jnp))
                    pj = jnp.asarray(pose)
                    row.append(timeit(lambda f=f, pj=pj: jax.block_until_ready(f(pj)),
                                      reps))
            print(f"| {n:,} | {name} | " + " | ".join(f"{v:.2f}" for v in row) + " |",
                  flush=True)


if __name__ == "__main__":
    import sys
    if "--methods" in sys.argv:
        methods([int(a) for a in sys.argv[2:]] or [100, 1_000, 10_000])
    else:
        main()
