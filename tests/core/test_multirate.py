"""Discrete blocks at several rates: updates exactly at hits, outputs held,
and the documented order (outputs, then updates)."""

import numpy as np
import pytest

import avblocks as av


class Sampler(av.Block):
    """Discrete counter and sampler: y = (count, sampled time), updated at hits."""

    def __init__(self, period, offset=0.0):
        super().__init__()
        self.declare_periodic(period, offset)
        self.declare_discrete_state("count", np.zeros((1,)))
        self.declare_discrete_state("when", np.full((1,), -1.0))
        self.declare_output("y", (1, 2))

    def output(self, t, x, u, xp):
        return {"y": xp.stack([x["count"], x["when"]], axis=-1)}

    def update(self, t, x, u, xp):
        return {"count": x["count"] + 1, "when": xp.full((1,), t)}


def test_two_rates_update_exactly_at_hits_and_hold():
    d = av.Diagram()
    a = d.add(Sampler(0.1), name="a")
    b = d.add(Sampler(0.25), name="b")
    res = av.simulate(d, 1.0, dt=0.05, log=[a.y, b.y])
    t = res.t
    ya, yb = res[a.y][:, 0], res[b.y][:, 0]
    for k, tk in enumerate(t):
        # A hit at t outputs the state before that hit's update: hits at
        # 0, 0.1, ... strictly before tk have been applied.
        hits_a = np.arange(0, 1.0 + 1e-9, 0.1)
        hits_b = np.arange(0, 1.0 + 1e-9, 0.25)
        done_a = hits_a[hits_a < tk - 1e-9]
        done_b = hits_b[hits_b < tk - 1e-9]
        # output computed at the latest hit <= tk, from updates before it
        last_a = hits_a[hits_a <= tk + 1e-9].max()
        last_b = hits_b[hits_b <= tk + 1e-9].max()
        assert ya[k, 0] == np.sum(hits_a < last_a - 1e-9), (tk, ya[k])
        assert yb[k, 0] == np.sum(hits_b < last_b - 1e-9), (tk, yb[k])
        assert len(done_a) >= ya[k, 0] and len(done_b) >= yb[k, 0]
    # the sampled times are exactly the hit times
    assert set(np.round(ya[:, 1], 9)) - {-1.0} <= set(np.round(np.arange(0, 1.01, 0.1), 9))
    assert set(np.round(yb[:, 1], 9)) - {-1.0} == {0.0, 0.25, 0.5, 0.75}


def test_offset_hits():
    d = av.Diagram()
    a = d.add(Sampler(0.2, offset=0.1), name="a")
    res = av.simulate(d, 1.0, dt=0.1, log=[a.y])
    when = res[a.y][:, 0, 1]
    assert set(np.round(when, 9)) == {-1.0, 0.1, 0.3, 0.5, 0.7}


def test_period_not_multiple_of_dt_is_an_error():
    d = av.Diagram()
    d.add(Sampler(0.15), name="a")
    with pytest.raises(av.ShapeError, match="not a multiple"):
        av.simulate(d, 1.0, dt=0.1)


class Hold(av.Block):
    """Discrete block with feedthrough: y = u sampled at hits."""

    def __init__(self, period):
        super().__init__()
        self.declare_periodic(period)
        self.declare_input("u", (1, 1))
        self.declare_output("y", (1, 1))

    def output(self, t, x, u, xp):
        return {"y": u["u"]}


def test_periodic_output_held_between_hits_while_input_moves():
    d = av.Diagram()
    c = d.add(av.blocks.Clock(), name="c")
    g = d.add(av.blocks.Function(lambda t, u: u.reshape(1, 1), inputs={"u": ()},
                                 outputs={"y": (1, 1)}), name="g")
    h = d.add(Hold(0.25), name="h")
    d.connect(c.y, g.u)
    d.connect(g.y, h.u)
    res = av.simulate(d, 1.0, dt=0.05, log=[h.y])
    expect = np.floor(res.t / 0.25 + 1e-9) * 0.25
    assert np.allclose(res[h.y][:, 0, 0], expect)


def test_inherited_sample_time_follows_the_drivers():
    d = av.Diagram()
    c = d.add(av.blocks.Clock(), name="c")
    f = d.add(av.blocks.Function(lambda t, u: u.reshape(1, 1), inputs={"u": ()},
                                 outputs={"y": (1, 1)}), name="f")
    z = d.add(av.blocks.ZeroOrderHold(0.25), name="z")
    g = d.add(av.blocks.Gain(2.0), name="g")          # after a ZOH: discrete
    g2 = d.add(av.blocks.Gain(3.0), name="g2")        # after g: discrete too
    h = d.add(av.blocks.Gain(1.0), name="h")          # after the clock: continuous
    d.connect(c.y, f.u)
    d.connect(f.y, z.u)
    d.connect(z.y, g.u)
    d.connect(g.y, g2.u)
    d.connect(f.y, h.u)
    d.build()
    assert g.block.sample_time == av.Periodic(0.25)
    assert g2.block.sample_time == av.Periodic(0.25)
    assert h.block.sample_time == av.Continuous()
    res = av.simulate(d, 1.0, dt=0.05, log=[g2.y, h.y])
    assert np.allclose(res[g2.y][:, 0, 0], 6 * np.floor(res.t / 0.25 + 1e-9) * 0.25)
    assert np.allclose(res[h.y][:, 0, 0], res.t)
    # mixed rates: continuous
    d2 = av.Diagram()
    a = d2.add(Sampler(0.1), name="a")
    b = d2.add(Sampler(0.25), name="b")
    s = d2.add(av.blocks.Sum("+-"), name="s")
    d2.connect(a.y, s.u0)
    d2.connect(b.y, s.u1)
    d2.build()
    assert s.block.sample_time == av.Continuous()
