"""Why do agents fail the navigation task? A failure analysis of the task itself.

    python benchmarks/navigation_failures.py [EPISODES] [POLICY.npz]

Draws EPISODES resets of ``rl.functional("navigation")`` (the training and
evaluation distribution) and measures, independently of any controller:

- spawns in contact at t=0 (start discs touching an obstacle, a wall or
  another agent), and draws that missed the requested clearance/separation;
- the shortest collision-free path of each agent alone (Dijkstra on a
  0.02 m 8-connected grid of the free space inflated by the agent radius;
  an upper bound: grid paths are up to 8 % longer than straight ones)
  against what the horizon allows: at unit speed (any direction can be
  driven at 1 m/s) and at the diagonal speed sqrt(2) (no action is faster);
- pairs of goals closer than two radii (both agents cannot sit on their goals).

Then runs the scripted controller (and POLICY, a PPO actor, when given)
on the same episodes, mean action, and splits the failures: touched another
agent, touched an obstacle or a wall, ended away from the goal without any
contact, and (for the last) whether the path alone was too long.
"""

from __future__ import annotations

import sys

import numpy as np


def _free_grid(world, half, radius, res=0.02):
    from avblocks.environment.edges import point_segment_distance
    xs = np.arange(-half + res / 2, half, res)
    X, Y = np.meshgrid(xs, xs, indexing="ij")
    P = np.stack([X.ravel(), Y.ravel()], -1)
    s = np.asarray(world.segments, float).reshape(-1, 4)
    d = point_segment_distance(P[:, 0:1], P[:, 1:2], s[:, 0], s[:, 1], s[:, 2], s[:, 3], np)
    inside = world_inside(world, P)
    free = (d.min(-1) > radius) & ~inside
    return xs, free.reshape(X.shape)


def world_inside(world, P):
    """Points inside an obstacle (the scenario's rectangles)."""
    from avblocks.scenarios.navigation import OBSTACLES
    out = np.zeros(len(P), bool)
    for cx, cy, w, h in OBSTACLES:
        out |= (np.abs(P[:, 0] - cx) <= w / 2) & (np.abs(P[:, 1] - cy) <= h / 2)
    return out


def geodesic(xs, free, starts, goals):
    """Shortest 8-connected grid path lengths from starts to goals (inf if none)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import dijkstra
    n = len(xs)
    res = xs[1] - xs[0]
    idx = np.arange(n * n).reshape(n, n)
    rows, cols, w = [], [], []
    I, J = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    for di, dj in ((0, 1), (1, 0), (1, 1), (1, -1)):
        i2, j2 = I + di, J + dj
        ok = (i2 < n) & (j2 >= 0) & (j2 < n)
        ok[ok] &= free[I[ok], J[ok]] & free[i2[ok], j2[ok]]
        rows.append(idx[ok])
        cols.append(i2[ok] * n + j2[ok])
        w.append(np.full(ok.sum(), res * np.hypot(di, dj)))
    r, c, w = np.concatenate(rows), np.concatenate(cols), np.concatenate(w)
    G = coo_matrix((np.r_[w, w], (np.r_[r, c], np.r_[c, r])), shape=(n * n, n * n)).tocsr()

    def cell(p):
        i = np.clip(np.round((p - xs[0]) / res).astype(int), 0, n - 1)
        return i[:, 0] * n + i[:, 1]

    cs, cg = cell(starts), cell(goals)
    out = np.full(len(cs), np.inf)
    for lo in range(0, len(cs), 256):
        D = dijkstra(G, indices=cs[lo:lo + 256])
        out[lo:lo + 256] = D[np.arange(D.shape[0]), cg[lo:lo + 256]]
    return out


def rollout(env, law, keys):
    """Per-episode starts, goals and per-step (positions, collision, success)."""
    import jax
    import jax.numpy as jnp
    h = 1.5
    n = env.n

    def episode(key):
        state, obs = env.reset(key)
        p0 = obs[:, 2:4] * h
        g0 = p0 + obs[:, 0:2]

        def body(c, _):
            state, obs = c
            a = law(obs)
            state, obs, r, d, info = env.step_env(state, a)
            return (state, obs), (obs[:, 2:4] * h, info["collision"], info["success"])

        _, (p, col, suc) = jax.lax.scan(body, (state, obs), None, length=env.max_steps)
        c0 = state.Y[env.cd.index("task")]["collision"]
        return p0, g0, c0, p, col, suc

    del n, jnp
    return [np.asarray(a) for a in jax.jit(jax.vmap(episode))(keys)]


def main(episodes=1000, policy=None):
    import jax
    import jax.numpy as jnp

    from avblocks import rl
    from avblocks.controllers.policy import mlp
    from avblocks.scenarios import navigation as nav
    env = rl.functional("navigation")
    half, r, gr, horizon = 1.5, 0.1, 0.15, env.max_steps * env.control_dt
    world = nav.arena(half)
    keys = jax.random.split(jax.random.PRNGKey(1234), episodes)
    edges = nav._obstacle_edges(world)
    law = nav.scripted_law(edges, half, 1.0, r)

    def scripted(obs):
        p = obs[:, 2:4] * half
        return law(0.0, p, p + obs[:, 0:2], jnp)

    ctrls = {"scripted": scripted}
    if policy:
        w = {k: jnp.asarray(v, jnp.float32) for k, v in np.load(policy).items()
             if k[0] in "wb" and k[1:].isdigit()}
        ctrls["policy"] = lambda obs: jnp.clip(mlp(w, obs, jnp), -1.0, 1.0)

    runs = {k: rollout(env, f, keys) for k, f in ctrls.items()}
    p0, g0, c0 = runs["scripted"][:3]
    E, N = p0.shape[:2]
    iu = np.triu_indices(N, 1)
    dp0 = np.linalg.norm(p0[:, :, None] - p0[:, None], axis=-1)[:, iu[0], iu[1]]
    dg0 = np.linalg.norm(g0[:, :, None] - g0[:, None], axis=-1)[:, iu[0], iu[1]]
    print(f"{E} episodes x {N} agents; horizon {horizon:g} s; arena {2 * half} m")
    print(f"  agents touching something at t=0 : {c0.mean():.2%} "
          f"(episodes with one: {c0.any(1).mean():.2%})")
    print(f"  start pairs closer than 0.5 m (the requested separation): "
          f"{(dp0 < 0.5).mean():.2%}; closer than 2 radii: {(dp0 < 2 * r).mean():.2%}")
    print(f"  goal pairs closer than 0.5 m: {(dg0 < 0.5).mean():.2%}; "
          f"closer than 2 radii: {(dg0 < 2 * r).mean():.2%}")
    xs, free = _free_grid(world, half, r)
    geo = geodesic(xs, free, p0.reshape(-1, 2), g0.reshape(-1, 2)).reshape(E, N)
    need = np.maximum(geo - gr, 0.0)
    straight = np.linalg.norm(g0 - p0, axis=-1)
    print(f"  straight-line distance: mean {straight.mean():.2f} m, max {straight.max():.2f}; "
          f"shortest free path: mean {geo[np.isfinite(geo)].mean():.2f} m, "
          f"max {geo[np.isfinite(geo)].max():.2f}, unreachable {np.isinf(geo).mean():.2%}")
    print(f"  straight distance / 1 m/s > horizon: {(straight - gr > horizon).mean():.2%}; "
          f"free path / 1 m/s > horizon: {(need > horizon).mean():.2%}; "
          f"free path / sqrt(2) m/s > horizon: {(need / np.sqrt(2) > horizon).mean():.2%}")
    print(f"  free path / 1 m/s > 80% of the horizon: {(need > 0.8 * horizon).mean():.2%}")
    for name, (_, _, _, p, col, suc) in runs.items():
        ok = suc[:, -1]
        hit = col.any(1)
        d = np.linalg.norm(p[:, :, :, None] - p[:, :, None], axis=-1)      # E,T,N,N
        d = d + np.eye(N) * 1e3
        agent_hit = (d.min(-1) <= 2 * r + 1e-6).any(1)                    # E,N
        wall_hit = hit & ~agent_hit
        away = ~ok & ~hit
        print(f"{name}: success {ok.mean():.1%}; touched another agent {agent_hit.mean():.1%}, "
              f"touched only an obstacle/wall {wall_hit.mean():.1%}, "
              f"away from the goal without contact {away.mean():.1%} "
              f"(of which the free path alone needs > horizon at 1 m/s: "
              f"{(away & (need > horizon)).mean():.1%})")
        tfirst = np.where(col.any(1), col.argmax(1), -1)
        print(f"   first contact at step 0-4: {((tfirst >= 0) & (tfirst < 5)).mean():.1%}; "
              f"success among agents with free path < 0.5 horizon: "
              f"{ok[need < 0.5 * horizon].mean():.1%}, >= 0.5: "
              f"{ok[need >= 0.5 * horizon].mean():.1%}")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 1000,
         sys.argv[2] if len(sys.argv) > 2 else None)
