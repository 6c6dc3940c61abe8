"""NeighborSource radius mode traces: compiled runs equal NumPy runs."""

import numpy as np
import pytest

import avblocks as av
from avblocks.controllers import CollisionAvoidance, Flocking
from avblocks.controllers._graph import NeighborSource

pytest.importorskip("jax")


def test_collision_avoidance_sensing_range_compiles():
    rng = np.random.default_rng(2)
    n = 30
    d = av.Diagram()
    ag = d.add(av.vehicles.SingleIntegrator(rng.uniform(0, 6, (n, 2))), name="ag")
    goal = d.add(av.blocks.Constant(rng.uniform(0, 6, (n, 2))), name="goal")
    err = d.add(av.blocks.Sum("+-"), name="err")
    ca = d.add(CollisionAvoidance(n, 0.3, sensing_range=1.5, k_max=4), name="ca")
    d.connect(goal.y, err.u0)
    d.connect(ag.position, err.u1)
    d.connect(err.y, ca.velocity_nominal)
    d.connect(ag.position, ca.position)
    d.connect(ca.velocity, ag.velocity)
    a = av.simulate(d, 2.0, dt=0.05, log=["ag.position"])
    b = av.simulate(d, 2.0, dt=0.05, log=["ag.position"], backend="jax")
    np.testing.assert_allclose(b["ag.position"], a["ag.position"], rtol=1e-9, atol=1e-9)


def test_flocking_internal_neighbours_compile_and_equal_port_mode():
    rng = np.random.default_rng(4)
    n = 40
    q0, v0 = rng.uniform(0, 30, (n, 2)), rng.uniform(-1, 1, (n, 2))

    def build(internal):
        d = av.Diagram()
        fl = d.add(av.vehicles.DoubleIntegrator(q0, velocity0=v0), name="fl")
        kw = dict(neighbors="internal", k_max=8) if internal else {}
        law = d.add(Flocking(n, 5.0, **kw), name="law")
        d.connect(fl.position, law.position)
        d.connect(fl.velocity, law.velocity)
        d.connect(law.accel, fl.accel)
        if not internal:
            nb = d.add(av.environment.Neighbors(n, 8, radius=6.0, input="position"),
                       name="nb")
            d.connect(fl.position, nb.position)
            d.connect(nb.neighbors, law.neighbors)
        return d

    a = av.simulate(build(True), 3.0, dt=0.05, log=["fl.position"])
    b = av.simulate(build(True), 3.0, dt=0.05, log=["fl.position"], backend="jax")
    c = av.simulate(build(False), 3.0, dt=0.05, log=["fl.position"])
    np.testing.assert_allclose(b["fl.position"], a["fl.position"], rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(c["fl.position"], a["fl.position"], rtol=1e-9, atol=1e-9)


def test_radius_mode_owns_a_planned_search():
    b = Flocking(5, 2.0, neighbors="internal", k_max=3)
    assert isinstance(b.graph, NeighborSource)
    from avblocks.core.diagnostics import searches_of
    assert searches_of(b) == [b.graph.search] and b.graph.search.reach == 2.4
