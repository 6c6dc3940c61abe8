"""Environment throughput of the navigation task: env-steps/s and agent-steps/s.

Side by side in one process, at num_envs 1, 64 and 1024 with 4 agents each:

- ``avblocks``: ``rl.functional("navigation")`` (the diagram stepped by the
  compiled engine's traced step), a jitted ``lax.scan`` of 60 control steps
  of a fixed random policy, ``vmap``-ed over the copies;
- ``pure JAX``: the same dynamics and task written by hand in this file (a
  single integrator's Euler step, the same range rays, collision test and
  reward computed with the same xp kernels): the limit without the block
  machinery;
- ``VMAS``: its ``navigation`` scenario on CPU with the same numbers of
  environments and agents, when ``vmas`` is installed (extra ``rl-bench``;
  it pulls torch). Otherwise the column says so.

Each figure: the best of ``--repeats`` timed runs after one warm-up (the
compile excluded). Each step's observation is summed into the result
(as a policy would read it), so XLA cannot drop the sensing.

Run: ``python benchmarks/rl_throughput.py [--quick]``; prints a markdown
table and writes rl_throughput.png.
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def best_of(fn, repeats):
    fn()
    best = np.inf
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return best


def avblocks_runner(E, T):
    import jax
    import jax.numpy as jnp

    from avblocks import rl
    env = rl.functional("navigation")

    def episode(key):
        k0, k1 = jax.random.split(key)
        state, obs = env.reset(k0)

        def body(c, k):
            state, obs = c
            a = jax.random.uniform(k, (env.n, 2), minval=-1.0, maxval=1.0)
            state, obs, r, d, info = env.step_env(state, a)
            return (state, obs), r.sum() + 1e-3 * obs.sum()     # what a policy reads

        _, r = jax.lax.scan(body, (state, obs), jax.random.split(k1, T))
        return r.sum()

    f = jax.jit(lambda k: jnp.sum(jax.vmap(episode)(jax.random.split(k, E))))
    key = jax.random.PRNGKey(0)
    return lambda: f(key).block_until_ready()


def pure_jax_runner(E, T, n=4):
    """The navigation task written directly in JAX (same kernels)."""
    import jax
    import jax.numpy as jnp

    from avblocks.scenarios import _task as K
    from avblocks.scenarios.navigation import OBSTACLES
    edges = jnp.asarray(K.polygon_edges([K.rectangle(*o) for o in OBSTACLES]), jnp.float32)
    half, r, rmax, dt = 1.5, 0.1, 1.0, 0.1
    angles = jnp.linspace(-jnp.pi, jnp.pi, 12, endpoint=False)
    idx = K.others_index(n)

    def task(p, g, prev, hit):
        rel = g - p
        d = jnp.sqrt(jnp.sum(rel * rel, -1) + 1e-12)
        ranges = K.ray_ranges(p, angles, edges, half, p, r, rmax, jnp)
        rel_o = jnp.reshape(p[idx] - p[:, None, :], (n, -1))
        obs = jnp.concatenate([rel, p / half, ranges / rmax, rel_o], -1)
        col = ((jnp.min(K.segment_distance(p, edges, jnp), -1) < r) | K.inside(p, edges, jnp)
               | jnp.any(jnp.abs(p) > half - r, -1)
               | jnp.any(K.pairwise(p, jnp) < 2 * r, -1))
        at = d < 0.15
        gap_a = K.pairwise(p, jnp) - 2 * r
        near = jnp.sum(jnp.clip(1.0 - gap_a / 0.2, 0.0, 1.0), -1)
        gap = jnp.minimum(jnp.min(K.segment_distance(p, edges, jnp), -1),
                          jnp.min(half - jnp.abs(p), -1)) - r
        close = near + jnp.clip(1.0 - gap / 0.2, 0.0, 1.0)
        reward = 5.0 * (prev - d) + 0.1 * at - 2.5 * col - 0.5 * close
        return obs, reward, d, hit | col

    def episode(key):
        k0, k1, k2 = jax.random.split(key, 3)
        p = K.free_points(k0, n, half, edges, 0.25, jnp, min_sep=0.4)
        g = K.free_points(k1, n, half, edges, 0.25, jnp, min_sep=0.4)
        prev = jnp.sqrt(jnp.sum((g - p) ** 2, -1))
        hit = jnp.zeros(n, bool)

        def body(c, k):
            p, prev, hit = c
            a = jax.random.uniform(k, (n, 2), minval=-1.0, maxval=1.0)
            p = p + dt * a                       # single integrator, Euler (exact here)
            obs, rew, d, hit = task(p, g, prev, hit)
            return (p, d, hit), rew.sum() + 1e-3 * obs.sum()

        _, rs = jax.lax.scan(body, (p, prev, hit), jax.random.split(k2, T))
        return rs.sum()

    f = jax.jit(lambda k: jnp.sum(jax.vmap(episode)(jax.random.split(k, E))))
    key = jax.random.PRNGKey(0)
    return lambda: f(key).block_until_ready()


def vmas_runner(E, T, n=4):
    try:
        import torch
        import vmas
    except ImportError:
        return None
    env = vmas.make_env("navigation", num_envs=E, device="cpu", continuous_actions=True,
                        n_agents=n, seed=0)
    env.reset()

    def run():
        for _ in range(T):
            acts = [torch.rand(E, 2) * 2 - 1 for _ in range(n)]
            env.step(acts)

    return run


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="num_envs 1 and 64 only")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--plot", default="rl_throughput.png")
    a = ap.parse_args(argv)
    T, n = 60, 4
    sizes = [1, 64] if a.quick else [1, 64, 1024]
    rows = []
    for E in sizes:
        row = {"num_envs": E}
        for name, make in (("avblocks", avblocks_runner), ("pure JAX", pure_jax_runner),
                           ("VMAS", vmas_runner)):
            fn = make(E, T)
            if fn is None:
                row[name] = None
                continue
            s = best_of(fn, a.repeats)
            row[name] = E * T / s
        rows.append(row)
    print("| num_envs | avblocks env-steps/s | agent-steps/s | pure JAX env-steps/s "
          "| avblocks / pure JAX | VMAS env-steps/s |")
    print("|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        v = "not installed" if r["VMAS"] is None else f"{r['VMAS']:,.0f}"
        print(f"| {r['num_envs']} | {r['avblocks']:,.0f} | {r['avblocks'] * n:,.0f} | "
              f"{r['pure JAX']:,.0f} | {r['avblocks'] / r['pure JAX']:.2f} | {v} |")
    if a.plot:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, ax = plt.subplots(figsize=(6, 4))
        for name, style in (("avblocks", "o-"), ("pure JAX", "s--"), ("VMAS", "^:")):
            ys = [r[name] for r in rows]
            if all(y is not None for y in ys):
                ax.loglog(sizes, ys, style, label=name)
        ax.set_xlabel("num_envs (4 agents each)")
        ax.set_ylabel("env-steps / s")
        ax.set_title("navigation task throughput, CPU")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
        fig.tight_layout()
        fig.savefig(a.plot, dpi=110)
        print(f"wrote {a.plot}")
    return rows


if __name__ == "__main__":
    main()
