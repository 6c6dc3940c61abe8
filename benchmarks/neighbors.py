"""Neighbour search: SciPy k-d tree vs the traceable cell list.

Workload: a 2-D cloud at constant density (about 12 others within the
radius r = 1), each point asks for its k = 12 nearest others within r
(exact, ties by index). Columns, in milliseconds per query of all N points
(best of a few calls: the least disturbed by other load on a shared machine):

  kd-tree      scipy.spatial.cKDTree build + query (the NumPy engine's
               search: spatial.kd_nearest adds the exact tie order)
  cells-numpy  avblocks.utility.spatial.nearest, NumPy, sized per call
  cells-jax    the same function under jax.jit (x64, CPU), planned from the
               cloud (capacity with headroom), second call onwards

    python benchmarks/neighbors.py            # N = 1e2 .. 1e5
    python benchmarks/neighbors.py --quick    # N = 1e2 .. 1e4
    python benchmarks/neighbors.py --within   # traced radius search on a crowd

``--within`` (issue 32): the traced radius search (``spatial.within``, x64,
jit) on the constant-density cloud with a dense blob added (``--blob``
points within 0.3 of one place), so the plan's capacity is the blob's;
with the width classes (each chunk of 1024 rows takes the smallest width
that holds its most crowded row) against one width (the plan's, as
before), the two compiled functions timed alternately in one process,
median of the rounds, and their rows checked equal.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.spatial import cKDTree

from avblocks.utility import spatial as sp


def cloud(n, seed=0, neighbours=12.0, radius=1.0):
    side = np.sqrt(n * np.pi * radius ** 2 / neighbours)
    return np.random.default_rng(seed).uniform(0.0, side, (n, 2))


def timed(fn, reps):
    fn()
    ts = []
    for _ in range(reps):
        t = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t)
    return 1e3 * float(np.min(ts))


def within_widths(ns, blob, rounds):
    """``--within``: width classes against the plan's one width."""
    import jax
    import jax.numpy as jnp

    import avblocks.utility.spatial.queries as q
    jax.config.update("jax_enable_x64", True)
    import os
    r = 1.0
    print(f"traced within, radius {r}, blob of {blob}; load {os.getloadavg()[0]:.1f}")
    print("| N | capacity, hits | width classes ms | one width ms | ratio |")
    print("|---:|---|---:|---:|---:|")
    classes = q.width_classes
    for n in ns:
        rng = np.random.default_rng(1)
        p = np.concatenate([cloud(n - blob), rng.normal(0.5 * np.sqrt(n), 0.15, (blob, 2))])
        plan = sp.plan_cells(p, r)
        pj = jnp.asarray(p)
        fs = {}
        for name, wc in (("classes", classes), ("one", lambda cap, most=None: (int(cap),))):
            q.width_classes = wc
            try:
                f = jax.jit(lambda x: sp.within(plan, x, r, xp=jnp)[0])  # noqa: B023
                fs[name] = f.lower(pj).compile()
            finally:
                q.width_classes = classes
        a, b = np.asarray(fs["classes"](pj)), np.asarray(fs["one"](pj))
        assert np.array_equal(np.sort(a, 1), np.sort(b, 1)), "the two differ"
        ts = {"classes": [], "one": []}
        for _ in range(rounds):
            for name, f in fs.items():
                ts[name].append(timed(lambda f=f, pj=pj: jax.block_until_ready(f(pj)), 3))
        tc, to = float(np.median(ts["classes"])), float(np.median(ts["one"]))
        print(f"| {n} | {plan.capacity}, {plan.hits} | {tc:.2f} | {to:.2f} | {tc / to:.2f} |",
              flush=True)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--no-jax", action="store_true")
    ap.add_argument("--k", type=int, default=12)
    ap.add_argument("--within", action="store_true", help="width classes of within")
    ap.add_argument("--blob", type=int, default=150)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--n", type=int, nargs="*")
    a = ap.parse_args(argv)
    if a.within:
        within_widths(a.n or [2000, 10000], a.blob, a.rounds)
        return
    ns = [100, 1000, 10000] + ([] if a.quick else [100000])
    k, r = a.k, 1.0
    if not a.no_jax:
        import jax
        import jax.numpy as jnp
        jax.config.update("jax_enable_x64", True)
    print(f"{'N':>8} {'kd-tree':>10} {'cells-numpy':>12} {'cells-jax':>10}   (ms per call)")
    for n in ns:
        p = cloud(n)
        reps = 7 if n <= 10000 else 3

        def kd():
            return cKDTree(p).query(p, k=min(k + 1, n),  # noqa: B023 (timed at once, in the loop)
                                    distance_upper_bound=np.nextafter(r, np.inf))

        free = sp.CellList(r)
        t_kd = timed(kd, reps)
        t_np = timed(lambda: sp.nearest(free, p, r, k, xp=np), reps)  # noqa: B023 (timed at once, in the loop)
        t_jx = float("nan")
        if not a.no_jax:
            plan = sp.plan_cells(p, r)
            f = jax.jit(lambda q: sp.nearest(plan, q, r, k, xp=jnp)[:2])  # noqa: B023 (timed at once, in the loop)
            pj = jnp.asarray(p)
            ref = sp.nearest(free, p, r, k, xp=np)[0]
            assert np.array_equal(np.asarray(f(pj)[0]), ref), "jax and numpy differ"
            t_jx = timed(lambda: jax.block_until_ready(f(pj)), reps)  # noqa: B023 (timed at once, in the loop)
        print(f"{n:>8} {t_kd:>10.2f} {t_np:>12.2f} {t_jx:>10.2f}", flush=True)


if __name__ == "__main__":
    main()
