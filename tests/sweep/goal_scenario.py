"""A tiny test scenario: n single integrators converge to a goal under
``velocity = k (goal - position)`` (``ctl.k`` is a numeric block parameter),
so ``position(t) = goal + (position0 - goal) exp(-k t)``. With
``untraceable=True`` a NumPy-only block (shapely collision checks) joins."""

import numpy as np

import avblocks as av
from avblocks.blocks import Constant, Gain, Sum
from avblocks.vehicles import SingleIntegrator


def make_diagram(n=3, goal=1.0, seed=0, t_final=1.0, dt=0.05, refuse_goal=None,
                 untraceable=False):
    if refuse_goal is not None and float(goal) == float(refuse_goal):
        raise ValueError(f"goal {goal} refused on purpose")
    x0 = np.random.default_rng(int(seed)).uniform(-1.0, 1.0, (int(n), 2))
    d = av.Diagram("goal")
    fleet = d.add(SingleIntegrator(x0), name="fleet")
    g = d.add(Constant(np.full((int(n), 2), float(goal))), name="goal")
    err = d.add(Sum("+-"), name="err")
    ctl = d.add(Gain(1.0), name="ctl")
    d.connect(g.y, err.u0)
    d.connect(fleet.position, err.u1)
    d.connect(err.y, ctl.u)
    d.connect(ctl.y, fleet.velocity)
    if untraceable:                 # a NumPy-only block: ensembles must refuse it
        from avblocks.environment import Collision, World
        col = d.add(Collision(World(), int(n), input="position", method="shapely"),
                    name="col")
        d.connect(fleet.position, col.position)
    return d, {"t_final": float(t_final), "dt": float(dt), "solver": "rk4",
               "log": [fleet.position], "seed": int(seed)}
