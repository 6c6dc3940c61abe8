"""Quadrotors flown by a controller written for single integrators.

    python examples/05_quadrotors.py [N]

N quadrotors (default 8; 6-DoF rigid bodies, vehicles.Quadrotor) each get a
cascaded velocity -> attitude -> rate controller
(vehicles.QuadrotorVelocityControl), which together take the same
``velocity`` set-point as a 3D SingleIntegrator. The holonomic
HolonomicPointToPoint law, unchanged, then flies them from a ring on the
ground up to a smaller ring at 3 m and over to a third one at 4 m. Writes quadrotors.png
(3D paths and the altitudes).
"""

import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import avblocks as av  # noqa: E402

n = int(sys.argv[1]) if len(sys.argv) > 1 else 8
small = bool(os.environ.get("AVBLOCKS_EXAMPLE_SMALL"))
t_final = 4.0 if small else 20.0

a = 2 * np.pi * np.arange(n) / n
r = max(2.0, 0.5 * n / np.pi)                      # ring radius: >= 1 m between drones
start = np.column_stack([r * np.cos(a), r * np.sin(a), np.zeros(n)])
ring1 = start * [0.6, 0.6, 0.0] + [0.0, 0.0, 3.0]
ring2 = ring1 + [2 * r + 3.0, 0.0, 1.0]
waypoints = np.stack([ring1, ring2], axis=1)      # (N, 2, 3)

d = av.Diagram()
quad = av.vehicles.Quadrotor(start)
fleet = d.add(av.vehicles.velocity_controlled_quadrotor(quad), name="fleet")
drive = d.add(av.controllers.HolonomicPointToPoint(waypoints, gain=1.0, v_max=1.5,
                                                    radius=0.3), name="drive")
d.connect(fleet.position, drive.position)
d.connect(drive.velocity, fleet.velocity)
res = av.simulate(d, t_final, dt=0.005, log=[fleet.position, fleet.attitude, drive.done],
                  log_every=10, progress=False)

p = res[fleet.position]
fig = plt.figure(figsize=(11, 4.5))
ax = fig.add_subplot(1, 2, 1, projection="3d")
for i in range(n):
    ax.plot(p[:, i, 0], p[:, i, 1], p[:, i, 2], lw=1.2, color=f"C{i % 10}")
    ax.scatter(*p[-1, i], color=f"C{i % 10}", s=18)
ax.scatter(*waypoints.reshape(-1, 3).T, marker="x", color="k", s=12)
ax.set_xlabel("x [m]")
ax.set_ylabel("y [m]")
ax.set_zlabel("z [m]")
ax.set_box_aspect(np.ptp(p.reshape(-1, 3), axis=0) + 0.5)
ax.set_title(f"{n} quadrotors, HolonomicPointToPoint + velocity control")
az = fig.add_subplot(1, 2, 2)
az.plot(res.t, p[:, :, 2], lw=1)
az.set_xlabel("t [s]")
az.set_ylabel("altitude z [m]")
az.grid(alpha=0.3)
fig.tight_layout()
fig.savefig("quadrotors.png", dpi=100)
err = np.linalg.norm(p[-1] - ring2, axis=1).max()
print(f"{n} quadrotors, {t_final:g} s: {int(res[drive.done][-1].sum())} at their last "
      f"waypoint (largest distance {err:.2f} m); wrote quadrotors.png")
