"""N unicycles through their own waypoints: the README's twenty lines.

    python examples/01_waypoints.py [N]
"""

import sys

import numpy as np

import avblocks as av

N = int(sys.argv[1]) if len(sys.argv) > 1 else 300
d = av.Diagram()
fleet = d.add(av.vehicles.Unicycle(pose0=av.utility.random_poses(N, area=(100, 100), seed=1)),
              name="fleet")
goals = np.random.default_rng(2).uniform(0, 100, (N, 3, 2))      # 3 waypoints each
drive = d.add(av.controllers.PointToPoint(goals, d=0.1, gain=1.0, v_max=1.0), name="drive")
d.connect(fleet.pose, drive.pose)
d.connect(drive.cmd, fleet.cmd)

res = av.simulate(d, t_final=30.0, dt=0.01, solver="rk4", log=[fleet.pose], log_every=10)
print(res)
print(f"{N} agents, 30 s simulated in {res.meta['wall_time']:.2f} s "
      f"({res.meta['realtime_factor']:.0f}x real time)")
