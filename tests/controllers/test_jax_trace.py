"""A point-to-point leader with a leader-follower wedge (tree levels inside
one block) traces under JAX and matches the NumPy run: the controllers are
pure functions of their inputs."""

import numpy as np
import pytest

import avblocks as av


def build(n=7):
    leader, l_ref, a_ref = av.controllers.formation("wedge", n, 1.5)
    p0 = np.column_stack([-np.arange(n) * 1.0, np.linspace(-2, 2, n), np.zeros(n)])
    d = av.Diagram()
    f = d.add(av.vehicles.Unicycle(pose0=p0), name="fleet")
    p2p = d.add(av.controllers.PointToPoint([[20.0, 5.0], [40.0, -5.0]], n=n, d=0.2,
                                            v_max=0.8), name="p2p")
    lf = d.add(av.controllers.LeaderFollower(leader, l_ref=l_ref, alpha_ref=a_ref, d=0.2),
               name="lf")
    d.connect(f.pose, p2p.pose)
    d.connect(f.pose, lf.pose)
    d.connect(p2p.cmd, lf.cmd_in)
    d.connect(lf.cmd, f.cmd)
    return d


@pytest.mark.jax
def test_leader_follower_wedge_traced_under_jax():
    pytest.importorskip("jax")
    from avblocks.core.jax_backend import simulate_jax

    ref = av.simulate(build(), 20.0, dt=0.01, log=["fleet.pose", "lf.cmd", "lf.error"])
    got = simulate_jax(build(), 20.0, dt=0.01, log=["fleet.pose", "lf.cmd", "lf.error"])
    assert np.max(np.abs(got["fleet.pose"] - ref["fleet.pose"])) < 1e-9
    assert np.max(np.abs(got["lf.cmd"] - ref["lf.cmd"])) < 1e-6
    # and the formation did settle (errors small at the end)
    assert np.max(np.abs(ref["lf.error"][-1])) < 0.05
