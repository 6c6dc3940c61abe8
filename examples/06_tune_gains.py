"""Tune leader-follower gains by gradient descent through a whole run (JAX).

    python examples/06_tune_gains.py [ITERATIONS]

A leader drives a slow curve; four followers start off their places in a
wedge and follow it with the leader-follower law of the AVLib paper (eqs.
2-5). The cost of a run is the formation error plus a price on the
followers' commands,

    J(k_l, k_alpha) = sum_t  |e(t)|^2 dt  +  rho * sum_t |u_f(t)|^2 dt,

so that infinitely stiff gains are not the answer. ``av.compile`` traces
the diagram once; ``runner.value_and_grad`` gives J and dJ/dk by reverse
mode through all 1000 steps, with the gains passed in as data (no
recompilation per iteration). Gradient descent on log-gains (they stay
positive) lowers J; the tuned gains are then checked on the NumPy engine.
Writes tune_gains.png: J per iteration, and the errors before and after.
"""

import os
import sys

import matplotlib

matplotlib.use("Agg")
import jax.numpy as jnp  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import avblocks as av  # noqa: E402

iterations = int(sys.argv[1]) if len(sys.argv) > 1 else 25
small = bool(os.environ.get("AVBLOCKS_EXAMPLE_SMALL"))
if small:
    iterations = min(iterations, 4)
n, dt, t_final, rho = 5, 0.02, 6.0 if small else 20.0, 0.05

leader, l_ref, alpha_ref = av.controllers.formation("wedge", n, 1.5)
follower = leader >= 0
rng = np.random.default_rng(3)
pose0 = np.zeros((n, 3))
pose0[:, 0] = -np.arange(n) * 1.5 + rng.uniform(-0.8, 0.8, n)
pose0[:, 1] = rng.uniform(-2.0, 2.0, n)
pose0[:, 2] = rng.uniform(-0.6, 0.6, n)


def roots(t, xp):
    """The leader's command: 1 m/s on a gentle S-curve (followers' rows unused)."""
    return xp.stack([xp.ones(n), 0.2 * xp.sin(0.3 * t) * xp.ones(n)], axis=-1)


d = av.Diagram()
fleet = d.add(av.vehicles.Unicycle(pose0=pose0), name="fleet")
drive = d.add(av.blocks.Function(roots, outputs={"cmd": (n, 2)}), name="drive")
lf = d.add(av.controllers.LeaderFollower(leader, l_ref, alpha_ref, d=0.2, k_l=0.3,
                                         k_alpha=0.3), name="lf")
d.connect(fleet.pose, lf.pose)
d.connect(drive.cmd, lf.cmd_in)
d.connect(lf.cmd, fleet.cmd)

runner = av.compile(d, t_final, dt=dt, log=[lf.error, lf.cmd])


def cost(res):
    """J of a run (jax.numpy: it is differentiated)."""
    err = res[lf.error][:, follower]
    cmd = res[lf.cmd][:, follower]
    return dt * (jnp.sum(err ** 2) + rho * jnp.sum(cmd ** 2))


def gains(z):
    return {"lf.k_l": np.exp(z[0]), "lf.k_alpha": np.exp(z[1])}


z = np.log([0.3, 0.3])          # log-gains, shared by all followers
history = []
step, prev = 0.3, None
for it in range(iterations):
    J, g = runner.value_and_grad(cost, ["lf.k_l", "lf.k_alpha"], params=gains(z))
    # dJ/dz = sum over followers of dJ/dk_i * k (the shared gain is broadcast)
    gz = np.array([g["lf.k_l"].sum(), g["lf.k_alpha"].sum()]) * np.exp(z)
    history.append((J, *np.exp(z)))
    if prev is not None and J > prev:
        step *= 0.5                     # overshoot: shorter steps
    prev = J
    print(f"iteration {it:2d}: k_l = {np.exp(z[0]):.3f}  k_alpha = {np.exp(z[1]):.3f}"
          f"  J = {J:8.4f}")
    z = z - step * gz / max(np.linalg.norm(gz), 1e-12)
history = np.array(history)
best = history[np.argmin(history[:, 0])]

# the tuned gains on the NumPy engine: the same cost, the errors before/after
before = av.simulate(d, t_final, dt=dt, log=[lf.error, lf.cmd], progress=False)
after = av.simulate(d, t_final, dt=dt, log=[lf.error, lf.cmd], progress=False,
                    params={"lf.k_l": best[1], "lf.k_alpha": best[2]})
J_np = dt * (np.sum(after[lf.error][:, follower] ** 2)
             + rho * np.sum(after[lf.cmd][:, follower] ** 2))

fig, (ax, ae) = plt.subplots(1, 2, figsize=(11, 4.2))
ax.plot(history[:, 0], "o-", ms=3)
ax.set_xlabel("gradient step")
ax.set_ylabel("cost J")
ax.set_title(f"J: {history[0, 0]:.3f} -> {best[0]:.3f} "
             f"(k_l {history[0, 1]:.2f} -> {best[1]:.2f}, "
             f"k_alpha {history[0, 2]:.2f} -> {best[2]:.2f})", fontsize=9)
ax.grid(alpha=0.3)
for res, style, label in ((before, "--", "initial gains"), (after, "-", "tuned gains")):
    e = np.linalg.norm(res[lf.error][:, follower], axis=-1).max(axis=1)
    ae.semilogy(res.t, e + 1e-12, style, label=label)
ae.set_xlabel("t [s]")
ae.set_ylabel("largest follower error |(l, alpha) err|")
ae.legend()
ae.grid(alpha=0.3)
fig.tight_layout()
fig.savefig("tune_gains.png", dpi=100)
print(f"J {history[0, 0]:.4f} -> {best[0]:.4f} (NumPy engine: {J_np:.4f}); "
      f"compilations: {runner.compilations}; wrote tune_gains.png")
