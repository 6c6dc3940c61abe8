"""Cost of controller evaluations: ns per agent-step (one output() call).

LeaderFollower (a 4-level tree) at N = 1,000 and 100,000; Consensus and
Flocking on a range-limited proximity graph (neighbours from a k-d tree,
mean degree held constant as N grows by scaling the arena) at N = 1,000 and
10,000. With constant degree the cost per agent grows like log N (tree
query), not like N (which an all-pairs N^2 law would give).

Run: ``.venv/bin/python benchmarks/controllers.py``; prints a markdown table.
"""

from __future__ import annotations

import time

import numpy as np

from avblocks.controllers import Consensus, Flocking, LeaderFollower
from avblocks.environment.neighbors import radius_neighbors


def timeit(fn, min_time=0.5):
    fn()
    reps, t0 = 0, time.perf_counter()
    while True:
        fn()
        reps += 1
        el = time.perf_counter() - t0
        if el >= min_time:
            return el / reps


def leader_follower(n):
    rng = np.random.default_rng(0)
    leader = np.maximum((np.arange(n) - 1) // 4, -1)      # 4-ary tree
    leader[0] = -1
    lf = LeaderFollower(leader, 1.0, 0.3)
    u = {"pose": rng.uniform(-50, 50, (n, 3)), "cmd_in": rng.uniform(0, 1, (n, 2))}
    return lambda: lf.output(0.0, {}, u, np), f"depth {len(lf.levels) - 1}"


def swarm(kind, n):
    rng = np.random.default_rng(0)
    side = np.sqrt(n / 2.0)                    # density 2 agents / m^2
    pos = rng.uniform(0, side, (n, 2))
    vel = rng.normal(size=(n, 2))
    r, k = 1.2, 16
    if kind == "consensus":
        blk = Consensus(n, radius=r, k_max=k)
        return lambda: blk.output(0.0, {}, {"position": pos}, np)
    blk = Flocking(n, 1.0, r=r, neighbors="internal", k_max=k)
    return lambda: blk.output(0.0, {}, {"position": pos, "velocity": vel}, np)


def neighbors_only(n):
    rng = np.random.default_rng(0)
    pos = rng.uniform(0, np.sqrt(n / 2.0), (n, 2))
    return lambda: radius_neighbors(pos, 1.2, 16)


def main():
    rows = []
    for n in (1_000, 100_000):
        fn, note = leader_follower(n)
        rows.append(("LeaderFollower", n, timeit(fn) / n * 1e9, note))
    for kind in ("consensus", "flocking"):
        for n in (1_000, 10_000):
            rows.append((kind.capitalize() + " (radius graph)", n,
                         timeit(swarm(kind, n)) / n * 1e9, "k-d tree inside"))
    for n in (1_000, 10_000):
        rows.append(("  of which radius_neighbors", n, timeit(neighbors_only(n)) / n * 1e9,
                     ""))
    print("| block | N | ns / agent-step | note |")
    print("|---|---:|---:|---|")
    for name, n, ns, note in rows:
        print(f"| {name} | {n:,} | {ns:,.0f} | {note} |")


if __name__ == "__main__":
    main()
