"""Quadrotors circling at different heights, to watch live in 3D.

    avblocks run examples/07_live_quadrotors.py --live
    avblocks run examples/07_live_quadrotors.py --live --set n=200

Each agent is a :class:`~avblocks.vehicles.Quadrotor` flown by its velocity
controller (``velocity_controlled_quadrotor``); a Function block commands a
velocity that pulls it onto a circle of radius ``radius`` (gain ``k``),
along it at ``speed``, and to its own height. The live view draws the
``position``/``attitude`` outputs as darts in 3D with trails; the numeric
parameters of the blocks appear as controls.
"""

from __future__ import annotations

import numpy as np

import avblocks as av


def make_diagram(n=12, radius=6.0, speed=2.0, k=1.0, seed=1):
    rng = np.random.default_rng(seed)
    ang = np.linspace(0, 2 * np.pi, n, endpoint=False)
    z_ref = np.linspace(2.0, 6.0, n)
    p0 = np.c_[0.5 * radius * np.cos(ang), 0.5 * radius * np.sin(ang),
               np.zeros(n)] + rng.normal(0, 0.1, (n, 3))

    def velocity(t, position, xp):
        x, y, z = position[:, 0], position[:, 1], position[:, 2]
        r = xp.sqrt(x * x + y * y) + 1e-9
        radial = k * (radius - r)
        vx = radial * x / r - speed * y / r
        vy = radial * y / r + speed * x / r
        return xp.stack([vx, vy, 1.5 * (z_ref - z)], axis=1)

    d = av.Diagram("circling")
    quad = av.vehicles.Quadrotor(p0)
    uav = d.add(av.vehicles.velocity_controlled_quadrotor(quad), name="uav")
    law = d.add(av.blocks.Function(velocity, inputs={"position": (n, 3)},
                                   outputs={"velocity": (n, 3)}), name="law")
    d.connect(uav.position, law.position)
    d.connect(law.velocity, uav.velocity)
    sim = {"t_final": 60.0, "dt": 0.01, "log": [uav.position, uav.attitude],
           "log_every": 5}
    return d, sim


if __name__ == "__main__":
    import os
    d, sim = make_diagram()
    live = True
    if os.environ.get("AVBLOCKS_EXAMPLE_SMALL"):      # the examples test: short, no pacing
        sim["t_final"], live = 0.5, {"realtime": None, "verbose": False}
    res = av.simulate(d, **sim, live=live)
    print(res.meta["live"]["ended_by"], f"t = {res.t[-1]:g} s")
