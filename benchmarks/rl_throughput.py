"""Environment throughput of the navigation task: env-steps/s and agent-steps/s.

Side by side in one process, at num_envs 1, 64 and 1024 with 4 agents each,
60 control steps of uniform random actions per rollout:

- ``avblocks``: ``rl.functional("navigation")`` (the diagram stepped by the
  compiled engine's traced step), a jitted ``lax.scan`` of the control
  steps, ``vmap``-ed over the copies;
- ``pure JAX``: the same dynamics and task written by hand in this file
  (:func:`navigation_task`: a single integrator's Euler step, range rays,
  collision test and reward as dense kernels: every ray against every
  edge, every pair of agents): the limit without the block machinery (the
  diagram uses the library's ``RangeSensor`` and ``Collision`` blocks,
  edge-grid method). ``tests/benchmarks`` checks that it computes the
  diagram's numbers;
- ``VMAS`` (``benchmarks/rl_vmas.py``, when ``vmas`` and torch are
  installed: extra ``rl-bench``; otherwise the columns say "not
  installed"): its stock ``navigation`` scenario with our sizes (4 agents
  of radius 0.1 in ``[-1.5, 1.5]^2``, 12 lidar rays of range 1.0), and the
  same scenario with our rectangles and the arena's walls added as
  colliding landmarks seen by the lidar (the closest like-for-like), each
  with torch on 1 and on 2 threads (``torch.set_num_threads``).

What differs between the simulations (the work per step is comparable, not
identical):

- dynamics: VMAS integrates forces (mass 1, drag 0.25, 2 physics
  substeps per 0.1 s step) and resolves contacts with penalty forces
  between every pair of colliding entities; ours is kinematic (a velocity
  command, one Euler step of 0.1 s) with contact *detection* (the
  ``Collision`` block flags a touch, nothing pushes back);
- observation: VMAS's agent sees its position, velocity, goal offset and
  12 lidar readings (18 numbers); ours its goal offset, scaled position,
  12 ranges and the other agents' offsets nearest first (22 numbers);
- reward: VMAS's shaped distance plus an agent-agent collision penalty;
  ours progress, goal bonus, contact and closeness penalties (the
  closeness term measures every agent against every edge);
- stock VMAS has no obstacles and its lidar sees only agents; its arena is
  a clamp on the positions (``enforce_bounds``), not walls;
- VMAS steps in Python over agents and entity pairs (torch eager, float32,
  one call per operation); ours is one compiled XLA program per rollout.

Each figure: the best of ``--repeats`` timed runs after one warm-up (the
compile excluded), the columns timed in turn within each repeat; the
ratio of the medians is printed too, and the load average before and
after (the machine may be shared). Each step's observation is summed into
the result (as a policy would read it), so XLA cannot drop the sensing;
VMAS computes every agent's observation, reward and info in ``env.step``.
``--xla-threads ROUNDS`` instead runs our two columns in subprocesses with
XLA's default threads and with one thread (``XLA_FLAGS``), alternated.

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


def avblocks_runner(E, T, **task):
    """Our column; ``task``: navigation scenario parameters (``obstacles=()``:
    the open arena, only its four walls, the like-for-like of VMAS's stock
    scenario)."""
    import jax
    import jax.numpy as jnp

    from avblocks import rl
    env = rl.functional("navigation", **task)

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
# obstacle, every pair of agents): what the diagram's blocks (RangeSensor,
# Collision, the task block) compute, without the block machinery, with the
# same algorithms (the rectangles as boxes in closed form, reductions that
# XLA fuses, ranks rather than a sort) and what only a hand-written version
# can use: the arena's walls as the exit from the arena (valid inside it).

def _red(x, axis, how, xp):
    """min or sum over a short axis; under JAX as a ``lax.reduce`` that XLA's
    CPU backend fuses (its plain min/sum reductions go to a slow library
    kernel for rows this short)."""
    if xp is np:
        return (np.min if how == "min" else np.sum)(x, axis=axis)
    from jax import lax
    if how == "min":
        return lax.reduce(x, xp.asarray(np.inf, x.dtype),
                          lambda a, b: xp.where(a < b, a, b), (axis % x.ndim,))
    return lax.reduce(x, xp.asarray(0, x.dtype), lambda a, b: a - (-b), (axis % x.ndim,))


def _rays(p, ca, sa, ica, ica_y, box, half, r, rmax, xp):
    """(n, R) ranges along directions (ca, sa) (R,): the boxes (slabs), the
    arena's walls (its exit), the other discs; layout (n, item, R)."""
    ox, oy = p[:, 0, None, None], p[:, 1, None, None]                  # (n, 1, 1)
    x0, y0, x1, y1 = (box[:, k, None] for k in range(4))               # (B, 1)
    ax, bx = (x0 - ox) * ica, (x1 - ox) * ica
    ay, by = (y0 - oy) * ica_y, (y1 - oy) * ica_y
    near = xp.maximum(xp.minimum(ax, bx), xp.minimum(ay, by))
    far = xp.minimum(xp.maximum(ax, bx), xp.maximum(ay, by))
    t = xp.where((near <= far) & (far >= 0), xp.where(near >= 0, near, far), np.inf)
    t = _red(t, 1, "min", xp)                                          # (n, R)
    wx = (xp.where(ca >= 0, half, -half) - p[:, 0:1]) * ica            # the walls
    wy = (xp.where(sa >= 0, half, -half) - p[:, 1:2]) * ica_y
    t = xp.minimum(t, xp.minimum(wx, wy))
    fx = p[None, :, 0] - p[:, 0:1]                                     # (n, n): j - i
    fy = p[None, :, 1] - p[:, 1:2]
    ff = (fx * fx + fy * fy)[..., None]
    tca = fx[..., None] * ca + fy[..., None] * sa                      # (n, n, R)
    disc = r * r - (ff - tca * tca)
    th = tca - xp.sqrt(xp.maximum(disc, 0.0))
    inside = ff <= r * r                                               # in a disc: 0
    hit = (disc >= 0) & (th >= 0) | inside
    other = ~np.eye(p.shape[0], dtype=bool)[..., None]
    th = xp.where(hit & other, xp.where(inside, 0.0, th), np.inf)
    return xp.minimum(xp.minimum(t, _red(th, 1, "min", xp)), rmax)


def _free(key, n, half, box, c, min_sep, jnp, tries=24):
    """``n`` points farther than ``c`` from the boxes and ``min_sep`` apart:
    the first of ``tries`` draws that is (the arena's margin by the range)."""
    import jax
    q = jax.random.uniform(key, (tries, n, 2), minval=-(half - c), maxval=half - c)
    ex = jnp.maximum(jnp.maximum(box[:, 0] - q[..., 0:1], q[..., 0:1] - box[:, 2]), 0.0)
    ey = jnp.maximum(jnp.maximum(box[:, 1] - q[..., 1:2], q[..., 1:2] - box[:, 3]), 0.0)
    ok = _red(ex * ex + ey * ey, -1, "min", jnp) > c * c                # (tries, n)
    chosen = []
    for i in range(n):
        oki = ok[:, i]
        for z in chosen:
            oki = oki & (jnp.sum((q[:, i] - z) ** 2, -1) >= min_sep ** 2)
        chosen.append(q[jnp.argmax(oki), i])
    return jnp.stack(chosen)


def navigation_task(n=4, xp=None):
    """The navigation task written by hand: ``(step, start)`` with
    ``step(p, g, prev, hit, a) -> (p, obs, reward, d, hit)`` (one control
    step of 0.1 s: the single integrator's Euler step, then the task's
    observation and reward at the new positions; ``prev`` is the distance
    to the goal before the step, ``hit`` the episode's collision flags) and
    ``start(key) -> (p, g)`` (JAX only). ``xp``: ``jax.numpy`` (default) or
    NumPy; the same numbers as the diagram's step for agents in the arena
    (tests/benchmarks)."""
    if xp is None:
        import jax.numpy as xp
    from avblocks.scenarios.navigation import OBSTACLES
    half, r, rmax, dt = 1.5, 0.1, 1.0, 0.1
    f32 = np.float32 if xp is not np else np.float64
    box = np.array([[cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2]
                    for cx, cy, w, h in OBSTACLES], f32)               # (B, 4)
    ang = np.linspace(-np.pi, np.pi, 12, endpoint=False)
    ca, sa = np.cos(ang).astype(f32), np.sin(ang).astype(f32)
    ica = (1.0 / np.where(ca == 0, 1e-30, ca)).astype(f32)             # 0: tiny positive
    ica_y = (1.0 / np.where(sa == 0, 1e-30, sa)).astype(f32)
    eye = np.eye(n, dtype=bool)
    slot = np.arange(n - 1)
    shift = slot[None, :] >= np.arange(n)[:, None]                     # column j -> agent j+1

    def step(p, g, prev, hit, a):
        p = p + dt * a                       # single integrator, Euler (exact here)
        rel = g - p
        d = xp.sqrt(rel[:, 0] ** 2 + rel[:, 1] ** 2 + 1e-12)
        ranges = _rays(p, ca, sa, ica, ica_y, box, half, r, rmax, xp)
        rel_a = p[None, :, :] - p[:, None, :]                          # (n, n, 2): j - i
        d2 = rel_a[..., 0] ** 2 + rel_a[..., 1] ** 2
        rel_x = xp.where(shift[..., None], rel_a[:, 1:], rel_a[:, :-1])  # (n, n-1, 2) others
        key = xp.where(shift, d2[:, 1:], d2[:, :-1])
        before = (key[:, None, :] < key[:, :, None]) | \
            ((key[:, None, :] == key[:, :, None]) & (slot[None, :] < slot[:, None]))
        rank = _red(before.astype(np.int32), -1, "sum", xp)            # (n, n-1)
        pick = (rank[:, :, None] == slot)[..., None]                   # (n, j, slot, 1)
        rel_o = _red(xp.where(pick, rel_x[:, :, None, :], 0.0), 1, "sum", xp)
        obs = xp.concatenate([rel, p / half, ranges / rmax, rel_o.reshape(n, -1)], -1)
        pair = xp.where(eye, np.inf, xp.sqrt(xp.where(eye, 1.0, d2) + 1e-12))
        qx, qy = p[:, 0:1], p[:, 1:2]                                  # boxes: closed form
        ex = xp.maximum(box[:, 0] - qx, qx - box[:, 2])                # (n, B)
        ey = xp.maximum(box[:, 1] - qy, qy - box[:, 3])
        ox, oy = xp.maximum(ex, 0.0), xp.maximum(ey, 0.0)
        out2 = ox * ox + oy * oy
        gap_b = xp.where(out2 > 0, xp.sqrt(xp.where(out2 > 0, out2, 1.0)),
                         -xp.maximum(ex, ey))                          # to the boundary
        gap_e = xp.minimum(_red(gap_b, 1, "min", xp),
                           xp.minimum(half - xp.abs(p[:, 0]), half - xp.abs(p[:, 1]))) - r
        col = (gap_e <= 0) | (_red(out2, 1, "min", xp) <= r * r) | \
            (_red(pair, 1, "min", xp) <= 2 * r)
        at = d < 0.15
        close = _red(xp.clip(1.0 - (pair - 2 * r) / 0.2, 0.0, 1.0), 1, "sum", xp) + \
            xp.clip(1.0 - gap_e / 0.2, 0.0, 1.0)
        reward = 5.0 * (prev - d) + 0.1 * at - 2.5 * col - 0.5 * close
        return p, obs, reward, d, hit | col

    def start(key):
        import jax
        k0, k1 = jax.random.split(key)
        return (_free(k0, n, half, box, 0.25, 0.5, xp),
                _free(k1, n, half, box, 0.25, 0.5, xp))

    return step, start


def pure_jax_runner(E, T, n=4):
    """The navigation task written directly in JAX (:func:`navigation_task`)."""
    import jax
    import jax.numpy as jnp
    step, start = navigation_task(n)

    def episode(key):
        k0, k2 = jax.random.split(key)
        p, g = start(k0)
        prev = jnp.sqrt(jnp.sum((g - p) ** 2, -1))
        hit = jnp.zeros(n, bool)

        def body(c, k):
            p, prev, hit = c
            a = jax.random.uniform(k, (n, 2), minval=-1.0, maxval=1.0)
            p, obs, rew, d, hit = step(p, g, prev, hit, a)
            return (p, d, hit), rew.sum() + 1e-3 * obs.sum()

        _, rs = jax.lax.scan(body, (p, prev, hit), jax.random.split(k2, T))
        return rs.sum()

    f = jax.jit(lambda k: jnp.sum(jax.vmap(episode)(jax.random.split(k, E))))
    key = jax.random.PRNGKey(0)
    return lambda: f(key).block_until_ready()


_VMAS = []


def _vmas_module():
    """``benchmarks/rl_vmas.py`` (loaded once), or None without vmas/torch."""
    if not _VMAS:
        try:
            import torch  # noqa: F401
            import vmas  # noqa: F401
        except ImportError:
            _VMAS.append(None)
            return None
        import importlib.util
        from pathlib import Path
        spec = importlib.util.spec_from_file_location(
            "rl_vmas", Path(__file__).with_name("rl_vmas.py"))
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        _VMAS.append(mod)
    return _VMAS[0]


def vmas_runner(variant, threads, device="cpu"):
    """A runner factory for VMAS (``benchmarks/rl_vmas.py``), or None
    without ``vmas``/torch."""
    def make(E, T, n=4):
        mod = _vmas_module()
        return None if mod is None else mod.runner(variant, E, T, n, threads, device)
    return make


OPEN = "avblocks, open arena"


def columns(vmas_device="cpu"):
    """(name, runner factory) of each column; on a GPU (``vmas_device``
    ``"cuda"``) VMAS has one column per scenario (torch's threads do not
    matter there)."""
    cols = [("avblocks", avblocks_runner), ("pure JAX", pure_jax_runner),
            (OPEN, lambda E, T: avblocks_runner(E, T, obstacles=()))]
    for variant in ("stock", "obstacles"):
        if vmas_device == "cpu":
            cols += [(f"VMAS {variant}, {k} thread{'s' * (k > 1)}", vmas_runner(variant, k))
                     for k in (1, 2)]
        else:
            cols.append((f"VMAS {variant}, {vmas_device}",
                         vmas_runner(variant, 1, vmas_device)))
    return cols


def measure(E, T, repeats, cols):
    """``{name: [seconds per run, ...]}``: one warm-up each (the compile),
    then ``repeats`` rounds, each timing every column once in turn."""
    fns = {}
    for name, make in cols:
        fn = make(E, T)
        if fn is not None:
            fn()
            fns[name] = fn
    times = {name: [] for name in fns}
    for _ in range(repeats):
        for name, fn in fns.items():
            t = time.perf_counter()
            fn()
            times[name].append(time.perf_counter() - t)
    return times


def _fmt(v):
    return "not installed" if v is None else f"{v:,.0f}"


def table(rows, n):
    vm = [c for c in rows[0] if c.startswith("VMAS")]
    has_open = rows[0].get(OPEN) is not None
    extra = [f"{c} env-steps/s" for c in ([OPEN] if has_open else []) + vm]
    if vm:
        extra += ["avblocks / best VMAS stock", "avblocks / best VMAS obstacles"]
        if has_open:
            extra += ["open arena / best VMAS stock"]
    print("| " + " | ".join(["num_envs", "avblocks env-steps/s", "agent-steps/s",
                             "pure JAX env-steps/s", "avblocks / pure JAX", *extra]) + " |")
    print("|---:" * (5 + len(extra)) + "|")
    for r in rows:
        ratios = []
        for kind in ("stock", "obstacles"):
            v = [r[c] for c in vm if kind in c and r[c] is not None]
            ratios.append(f"{r['avblocks'] / max(v):.1f}" if v else "-")
        if has_open:
            v = [r[c] for c in vm if "stock" in c and r[c] is not None]
            ratios.append(f"{r[OPEN] / max(v):.1f}" if v else "-")
        print(f"| {r['num_envs']} | {r['avblocks']:,.0f} | {r['avblocks'] * n:,.0f} | "
              f"{r['pure JAX']:,.0f} | {r['avblocks'] / r['pure JAX']:.2f} | " +
              "".join(f"{_fmt(r[c])} | " for c in ([OPEN] if has_open else []) + vm) +
              ("".join(f"{x} | " for x in ratios) if vm else ""))


def xla_threads(argv, rounds):
    """Our two columns with XLA's default threads and with one thread
    (``XLA_FLAGS``, set before jax starts: one subprocess each), alternated
    ``rounds`` times; prints the medians of each process's best."""
    import json
    import os
    import subprocess
    import sys
    import tempfile
    flag = "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"
    res = {"default": [], "1 thread": []}
    for _ in range(rounds):
        for name in res:
            env = dict(os.environ)
            if name == "1 thread":
                env["XLA_FLAGS"] = (env.get("XLA_FLAGS", "") + " " + flag).strip()
            with tempfile.NamedTemporaryFile(suffix=".json") as f:
                subprocess.run([sys.executable, __file__, *argv, "--jax-only", "--plot", "",
                                "--json", f.name], env=env, check=True,
                               stdout=subprocess.DEVNULL)
                with open(f.name) as g:
                    res[name].append(json.load(g))
    print(f"XLA threads ({rounds} alternated processes each, medians of their best):")
    print("| num_envs | column | default env-steps/s | 1 thread env-steps/s | 1 thread / default |")
    print("|---:|---|---:|---:|---:|")
    for i, row in enumerate(res["default"][0]):
        for col in ("avblocks", "pure JAX"):
            a = np.median([r[i][col] for r in res["default"]])
            b = np.median([r[i][col] for r in res["1 thread"]])
            print(f"| {row['num_envs']} | {col} | {a:,.0f} | {b:,.0f} | {b / a:.2f} |")
    return res


def main(argv=None):
    import os
    import sys
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="num_envs 1 and 64 only")
    ap.add_argument("--sizes", type=int, nargs="+", default=None, help="num_envs values")
    ap.add_argument("--steps", type=int, default=60, help="control steps per rollout")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--plot", default="rl_throughput.png")
    ap.add_argument("--jax-only", action="store_true", help="no VMAS columns")
    ap.add_argument("--vmas-device", default="cpu", help="torch device of VMAS (cpu, cuda)")
    ap.add_argument("--json", default="", help="also write the rows here")
    ap.add_argument("--xla-threads", type=int, default=0, metavar="ROUNDS",
                    help="compare XLA on its default threads and on one (subprocesses)")
    argv = sys.argv[1:] if argv is None else list(argv)
    a = ap.parse_args(argv)
    if a.xla_threads:
        rest = ["--sizes", *map(str, a.sizes or [1, 64, 1024]), "--steps", str(a.steps),
                "--repeats", str(a.repeats)]
        return xla_threads(rest, a.xla_threads)
    T, n = a.steps, 4
    sizes = a.sizes or ([1, 64] if a.quick else [1, 64, 1024])
    cols = columns(a.vmas_device)[:3 if a.jax_only else None]
    print(f"load average before: {os.getloadavg()[0]:.2f} ({os.cpu_count()} CPUs)")
    rows, medians = [], []
    for E in sizes:
        times = measure(E, T, a.repeats, cols)
        rows.append({"num_envs": E, **{c: E * T / min(times[c]) if c in times else None
                                       for c, _ in cols}})
        medians.append({c: E * T / np.median(times[c]) for c in times})
    print(f"load average after: {os.getloadavg()[0]:.2f}")
    print(f"best of {a.repeats} alternated runs after a warm-up, {T} steps, {n} agents per env:")
    table(rows, n)
    print("avblocks / pure JAX, ratio of the medians: " + ", ".join(
        f"{m['avblocks'] / m['pure JAX']:.2f} at {r['num_envs']}"
        for r, m in zip(rows, medians)))
    if a.json:
        import json
        with open(a.json, "w") as f:
            json.dump(rows, f)
    if a.plot:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, ax = plt.subplots(figsize=(6.5, 4.2))
        for (name, _), style in zip(cols, ("o-", "s--", "o:", "^:", "v:", "D-.", "x-.")):
            ys = [r[name] for r in rows]
            if all(y is not None for y in ys):
                ax.loglog(sizes, ys, style, label=name)
        ax.set_xlabel(f"num_envs ({n} agents each)")
        ax.set_ylabel("env-steps / s")
        import jax
        dev = jax.devices()[0]
        where = (f"CPU ({os.cpu_count()} cores)" if dev.platform == "cpu"
                 else dev.device_kind)
        ax.set_title(f"navigation task throughput, {where}")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(a.plot, dpi=110)
        print(f"wrote {a.plot}")
    return rows


if __name__ == "__main__":
    main()
