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


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--no-jax", action="store_true")
    ap.add_argument("--k", type=int, default=12)
    a = ap.parse_args(argv)
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
