"""Environment throughput of the navigation task: env-steps/s and agent-steps/s.

Side by side in one process, at num_envs 1, 64 and 1024 with 4 agents each:

- ``avblocks``: ``rl.functional("navigation")`` (the diagram stepped by the
  compiled engine's traced step), a jitted ``lax.scan`` of 60 control steps
  of a fixed random policy, ``vmap``-ed over the copies;
- ``pure JAX``: the same dynamics and task written by hand in this file (a
  single integrator's Euler step, range rays, collision test and reward as
  dense kernels: every ray against every edge, every pair of agents): the
  limit without the block machinery (the diagram uses the library's
  ``RangeSensor`` and ``Collision`` blocks, edge-grid method);
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


# ---------------------------------------------------------------- pure JAX
# The navigation task written by hand, dense (every ray against every
# edge, every pair of agents): what the diagram's blocks (RangeSensor,
# Collision, the task block) compute, without the block machinery.

def _edges(obstacles, half):
    """(E, 4) edges of the rectangles (cx, cy, w, h) and of the arena's border."""
    out = []
    for cx, cy, w, h in obstacles:
        x0, x1, y0, y1 = cx - w / 2, cx + w / 2, cy - h / 2, cy + h / 2
        v = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
        out.append(np.concatenate([v, np.roll(v, -1, axis=0)], axis=1))
    return np.concatenate(out)


def _seg_dist(p, e, jnp):
    """(n, E) distance from points p (n, 2) to the edges e (E, 4)."""
    a, ab = e[:, :2], e[:, 2:] - e[:, :2]
    ap = p[:, None, :] - a
    s = jnp.clip(jnp.sum(ap * ab, -1) / jnp.sum(ab * ab, -1), 0.0, 1.0)
    d = ap - s[..., None] * ab
    return jnp.sqrt(jnp.sum(d * d, -1))


def _inside(p, e, jnp):
    """(n,) inside an obstacle (crossing parity; obstacles do not overlap)."""
    x, y = p[:, 0:1], p[:, 1:2]
    x1, y1, x2, y2 = e[:, 0], e[:, 1], e[:, 2], e[:, 3]
    dy = jnp.where(y2 == y1, 1.0, y2 - y1)
    cross = ((y1 > y) != (y2 > y)) & (x < x1 + (y - y1) * (x2 - x1) / dy)
    return jnp.sum(cross, -1) % 2 == 1


def _rays(p, d, e, half, r, rmax, jnp):
    """(n, R) ranges along directions d (R, 2): edges, walls, other discs."""
    a, ev = e[:, :2], e[:, 2:] - e[:, :2]
    ao = a[None] - p[:, None]                                          # (n, E, 2)
    den = d[:, 0:1] * ev[None, :, 1] - d[:, 1:2] * ev[None, :, 0]      # (R, E)
    sd = jnp.where(jnp.abs(den) < 1e-12, 1e-12, den)
    t = (ao[:, None, :, 0] * ev[:, 1] - ao[:, None, :, 1] * ev[:, 0]) / sd
    u = (ao[:, None, :, 0] * d[None, :, None, 1] - ao[:, None, :, 1] * d[None, :, None, 0]) / sd
    t = jnp.min(jnp.where((t >= 0) & (u >= 0) & (u <= 1), t, jnp.inf), -1)
    dd = jnp.where(jnp.abs(d) < 1e-12, 1e-12, d)
    tw = (jnp.where(d > 0, half, -half)[None] - p[:, None, :]) / dd[None]   # (n, R, 2)
    t = jnp.minimum(t, jnp.min(jnp.maximum(tw, 0.0), -1))
    oc = p[None, :, :] - p[:, None, :]                                 # (n, m, 2)
    proj = jnp.einsum("nmk,rk->nrm", oc, d)
    disc = r * r - (jnp.sum(oc * oc, -1)[:, None, :] - proj * proj)
    th = proj - jnp.sqrt(jnp.maximum(disc, 0.0))
    n = p.shape[0]
    hit = (disc >= 0) & (th >= 0) & ~np.eye(n, dtype=bool)[:, None, :]
    t = jnp.minimum(t, jnp.min(jnp.where(hit, th, jnp.inf), -1))
    return jnp.minimum(t, rmax)


def _free(key, n, half, e, c, min_sep, jnp, tries=24):
    import jax
    q = jax.random.uniform(key, (tries, n, 2), minval=-(half - c), maxval=half - c)
    ok = ~_inside(q.reshape(-1, 2), e, jnp).reshape(tries, n) & \
        (jnp.min(_seg_dist(q.reshape(-1, 2), e, jnp), -1).reshape(tries, n) > c)
    chosen = []
    for i in range(n):
        oki = ok[:, i]
        for z in chosen:
            oki = oki & (jnp.sum((q[:, i] - z) ** 2, -1) >= min_sep ** 2)
        chosen.append(q[jnp.argmax(oki), i])
    return jnp.stack(chosen)


def pure_jax_runner(E, T, n=4):
    """The navigation task written directly in JAX (dense kernels above)."""
    import jax
    import jax.numpy as jnp

    from avblocks.scenarios.navigation import OBSTACLES
    half, r, rmax, dt = 1.5, 0.1, 1.0, 0.1
    edges = jnp.asarray(_edges(OBSTACLES, half), jnp.float32)
    ang = np.linspace(-np.pi, np.pi, 12, endpoint=False)
    dirs = jnp.asarray(np.stack([np.cos(ang), np.sin(ang)], -1), jnp.float32)
    j = np.arange(n - 1)[None, :]
    idx = j + (j >= np.arange(n)[:, None])
    eye = np.eye(n, dtype=bool)

    def task(p, g, prev, hit):
        rel = g - p
        d = jnp.sqrt(jnp.sum(rel * rel, -1) + 1e-12)
        ranges = _rays(p, dirs, edges, half, r, rmax, jnp)
        rel_o = p[idx] - p[:, None, :]
        rel_o = jnp.take_along_axis(rel_o, jnp.argsort(jnp.sum(rel_o ** 2, -1), -1)[..., None],
                                    axis=1).reshape(n, -1)
        obs = jnp.concatenate([rel, p / half, ranges / rmax, rel_o], -1)
        pair = jnp.where(eye, jnp.inf, jnp.sqrt(jnp.sum((p[:, None] - p[None]) ** 2, -1)))
        gap_e = jnp.minimum(jnp.min(_seg_dist(p, edges, jnp), -1),
                            jnp.min(half - jnp.abs(p), -1)) - r
        col = (gap_e <= 0) | _inside(p, edges, jnp) | jnp.any(pair <= 2 * r, -1)
        at = d < 0.15
        close = jnp.sum(jnp.clip(1.0 - (pair - 2 * r) / 0.2, 0.0, 1.0), -1) + \
            jnp.clip(1.0 - gap_e / 0.2, 0.0, 1.0)
        reward = 5.0 * (prev - d) + 0.1 * at - 2.5 * col - 0.5 * close
        return obs, reward, d, hit | col

    def episode(key):
        k0, k1, k2 = jax.random.split(key, 3)
        p = _free(k0, n, half, edges, 0.25, 0.5, jnp)
        g = _free(k1, n, half, edges, 0.25, 0.5, jnp)
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
