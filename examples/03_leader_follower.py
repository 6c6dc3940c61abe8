"""A three-level leader-follower cascade: leader -> follower -> follower -> follower.

    python examples/03_leader_follower.py [CHAINS]

CHAINS independent chains of four unicycles (default 3). Each chain's root
drives at 1 m/s, weaving (omega = 0.15 cos(0.2 t)); agent k + 1 follows agent k at
distance 1.5 m and tracking angle +-0.5 rad (an echelon), through the
feedback-linearized law of the AVLib paper (eqs. 2-5). One LeaderFollower
block computes all levels of all chains at once (level by level of the
leader tree). Writes leader_follower.png: the paths, and the errors
(l_ref - l, alpha_ref - alpha) of each level, which decay like exp(-K t)
although the leaders keep turning (the law feeds their velocities forward).
"""

import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import avblocks as av  # noqa: E402

chains = int(sys.argv[1]) if len(sys.argv) > 1 else 3
small = bool(os.environ.get("AVBLOCKS_EXAMPLE_SMALL"))
depth = 4                                     # root + 3 follower levels
n = chains * depth
t_final = 20.0 if small else 60.0

# agent c * depth + k is level k of chain c; level k follows level k - 1
level = np.tile(np.arange(depth), chains)
leader = np.where(level == 0, -1, np.arange(n) - 1)
alpha_ref = np.where(level % 2 == 1, 0.5, -0.5) * (level > 0)
l_ref = np.where(level > 0, 1.5, 0.0)

# start near the echelon: level k sits at its references from level k - 1
rng = np.random.default_rng(4)
rel = np.zeros((n, 2))
rel[:, 0] = -l_ref * np.cos(alpha_ref)          # behind its leader ...
rel[:, 1] = -l_ref * np.sin(alpha_ref)          # ... and aside (alpha > 0: right)
pose0 = np.zeros((n, 3))
for c in range(chains):
    rows = slice(c * depth, (c + 1) * depth)
    pose0[rows, :2] = np.cumsum(rel[rows], axis=0) + [0.0, 8.0 * c]
pose0[:, :2] += rng.uniform(-0.3, 0.3, (n, 2))


def roots(t, xp):
    """The roots' commands: 1 m/s, slowly weaving (followers' rows ignored)."""
    omega = 0.15 * xp.cos(0.2 * t) * xp.ones(n)
    return xp.stack([xp.ones(n), omega], axis=-1)


d = av.Diagram()
fleet = d.add(av.vehicles.Unicycle(pose0=pose0), name="fleet")
drive = d.add(av.blocks.Function(roots, outputs={"cmd": (n, 2)}), name="drive")
lf = d.add(av.controllers.LeaderFollower(leader, l_ref, alpha_ref, d=0.2, k_l=1.0,
                                         k_alpha=1.0), name="lf")
d.connect(fleet.pose, lf.pose)
d.connect(drive.cmd, lf.cmd_in)             # only the roots' rows are used
d.connect(lf.cmd, fleet.cmd)
res = av.simulate(d, t_final, dt=0.02, log=[fleet.pose, lf.error], log_every=5,
                  progress=False)

fig, (ax, ae) = plt.subplots(1, 2, figsize=(11, 4.5))
av.viz.plot_trajectories(res, fleet.pose, ax=ax)
ax.set_title(f"{chains} chains of {depth}: leader -> 3 follower levels")
err = np.abs(res[lf.error])
for k in range(1, depth):
    sel = level == k
    ae.semilogy(res.t, err[:, sel, 0].max(axis=1) + 1e-12, f"C{k}-", label=f"level {k}: |l err|")
    ae.semilogy(res.t, err[:, sel, 1].max(axis=1) + 1e-12, f"C{k}--",
                label=f"level {k}: |alpha err|")
ae.set_xlabel("t [s]")
ae.set_ylabel("largest error over chains [m, rad]")
ae.set_ylim(1e-6, 10)
ae.legend(fontsize=7, ncol=2)
ae.grid(alpha=0.3)
fig.tight_layout()
fig.savefig("leader_follower.png", dpi=100)
final = err[-1][level > 0].max()
print(f"{n} agents, {t_final:g} s; largest final error {final:.2e}; wrote leader_follower.png")
