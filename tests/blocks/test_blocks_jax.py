"""Every new block traces under JAX and matches the NumPy run."""

import numpy as np
import pytest

import avblocks as av
from avblocks import blocks as B


def diagram():
    d = av.Diagram()
    s = d.add(B.Sine(amplitude=np.ones((4, 2)) * [1.0, 3.0], frequency=0.8), name="s")
    rl = d.add(B.RateLimiter(2.0, period=0.05), name="rl")
    rc = d.add(B.RateLimiter([1.0, 4.0], initial=0.5), name="rc")
    sat = d.add(B.Saturation(-0.8, [0.5, 2.0]), name="sat")
    dz = d.add(B.DeadZone(-0.1, 0.1), name="dz")
    zoh = d.add(B.ZeroOrderHold(0.1, offset=0.05), name="zoh")
    z = d.add(B.UnitDelay(0.0, period=0.1), name="z")
    sel = d.add(B.Select([3, 1]), name="sel")
    g = d.add(B.Gather([0, 0, 1, 2]), name="g")
    cat = d.add(B.Concatenate(2), name="cat")
    dm = d.add(B.Demux(2), name="dm")
    mx = d.add(B.Mux(2), name="mx")
    i = d.add(B.Integrator(np.ones((6, 2))), name="i")
    f = d.add(B.Function(lambda t, x, r, xp: -x + xp.tanh(r), inputs={"x": (6, 2),
                                                                       "r": None},
                         outputs={"dx": (6, 2)}), name="f")
    d.connect(s.y, rl.u)
    d.connect(s.y, rc.u)
    d.connect(rl.y, sat.u)
    d.connect(sat.y, dz.u)
    d.connect(dz.y, zoh.u)
    d.connect(zoh.y, z.u)
    d.connect(z.y, sel.u)
    d.connect(rc.y, g.u)
    d.connect(sel.y, cat.u0)
    d.connect(g.y, cat.u1)
    d.connect(cat.y, dm.u)
    d.connect(dm.y1, mx.u0)
    d.connect(dm.y0, mx.u1)
    d.connect(i.y, f.x)
    d.connect(mx.y, f.r)
    d.connect(f.dx, i.u)
    return d, [i.y, mx.y, z.y, rc.y]


@pytest.mark.jax
def test_new_blocks_trace_under_jax_and_match_numpy():
    pytest.importorskip("jax")
    from avblocks.core.jax_backend import simulate_jax

    d, logs = diagram()
    ref = av.simulate(d, 1.0, dt=0.05, log=logs)
    d2, logs2 = diagram()
    got = simulate_jax(d2, 1.0, dt=0.05, log=logs2)
    for a, b in zip(logs, logs2):
        assert np.max(np.abs(np.asarray(got[b.path]) - ref[a])) < 1e-12, a.path
    assert np.ptp(ref[logs[1]]) > 0.5      # the chain carries a signal
