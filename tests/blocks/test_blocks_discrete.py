import numpy as np
import pytest

import avblocks as av
from avblocks.blocks import UnitDelay, ZeroOrderHold
from avblocks.core.check import check_block

F = 0.7   # Hz


def _sine_into(blk, t_final=2.0, dt=0.05):
    d = av.Diagram()
    a = d.add(av.blocks.Sine(amplitude=[1.0, 2.0], frequency=F), name="a")
    z = d.add(blk, name="z")
    d.connect(a.y, z.u)
    return av.simulate(d, t_final, dt=dt, log=[z.y, a.y]), z


def _last_hit(t, period, offset=0.0):
    return np.floor((t - offset) / period + 1e-9) * period + offset


@pytest.mark.parametrize("period", [0.05, 0.1, 0.25])
def test_unit_delay_outputs_input_one_period_earlier(period):
    res, z = _sine_into(UnitDelay(-5.0, period=period))
    t, y = res.t, res[z.y]
    tk = _last_hit(t, period)
    amp = np.array([1.0, 2.0])
    truth = amp * np.sin(2 * np.pi * F * (tk - period))[:, None]
    truth[tk < period - 1e-9] = -5.0                       # initial output
    np.testing.assert_allclose(y, truth, atol=1e-12)
    if period == 0.05:   # period = dt: y_k is exactly the logged input one step back
        np.testing.assert_allclose(y[1:], res["a.y"][:-1], atol=1e-12)


@pytest.mark.parametrize("period", [0.1, 0.25])
def test_zero_order_hold_samples_and_holds(period):
    res, z = _sine_into(ZeroOrderHold(period))
    t, y = res.t, res[z.y]
    tk = _last_hit(t, period)
    truth = np.array([1.0, 2.0]) * np.sin(2 * np.pi * F * tk)[:, None]
    np.testing.assert_allclose(y, truth, atol=1e-12)
    # constant between hits, jumps at hits
    held = np.isclose(tk, np.roll(tk, 1))
    assert np.all(np.diff(y, axis=0)[held[1:]] == 0)


def test_zero_order_hold_offset():
    d = av.Diagram()
    c = d.add(av.blocks.Clock(), name="c")
    h = d.add(ZeroOrderHold(0.25, offset=0.1), name="h")
    d.connect(c.y, h.u)
    res = av.simulate(d, 1.0, dt=0.05, log=[h.y])
    t = res.t
    truth = np.where(t < 0.1 - 1e-9, 0.0, _last_hit(t, 0.25, 0.1))
    np.testing.assert_allclose(res[h.y], truth, atol=1e-12)


def test_zero_order_hold_is_held_inside_solver_stages():
    # integrating a held clock gives a staircase integral, exact under RK4:
    # x(t) = sum over complete holds of t_k * T + t_last * (t - t_last)
    d = av.Diagram()
    c = d.add(av.blocks.Clock(), name="c")
    h = d.add(ZeroOrderHold(0.25), name="h")
    i = d.add(av.blocks.Integrator(0.0, agents=False), name="i")
    d.connect(c.y, h.u)
    d.connect(h.y, i.u)
    res = av.simulate(d, 2.0, dt=0.05, log=[i.y])
    t = res.t
    tk = _last_hit(t, 0.25)
    m = np.round(tk / 0.25)
    truth = 0.25 * 0.25 * m * (m - 1) / 2 + tk * (t - tk)
    np.testing.assert_allclose(res[i.y], truth, atol=1e-12)


def test_unit_delay_breaks_an_algebraic_loop_counter():
    # x_{k+1} = x_k + 1 through Sum and UnitDelay
    d = av.Diagram()
    one = d.add(av.blocks.Constant([1.0, 10.0]), name="one")
    s = d.add(av.blocks.Sum("++"), name="s")
    z = d.add(UnitDelay(np.zeros(2), period=0.1), name="z")
    d.connect(one.y, s.u0)
    d.connect(z.y, s.u1)
    d.connect(s.y, z.u)
    res = av.simulate(d, 1.0, dt=0.1, log=[z.y])
    np.testing.assert_allclose(res[z.y], np.arange(11)[:, None] * [1.0, 10.0], atol=1e-12)


def test_zero_order_hold_in_a_loop_is_an_algebraic_loop():
    d = av.Diagram()
    g = d.add(av.blocks.Gain(0.5), name="g")
    h = d.add(ZeroOrderHold(0.1), name="h")
    d.connect(g.y, h.u)
    d.connect(h.y, g.u)
    with pytest.raises(av.AlgebraicLoopError):
        d.build()


def test_unit_delay_shape_and_period_errors():
    d = av.Diagram()
    c = d.add(av.blocks.Constant(np.zeros((3, 2))), name="c")
    z = d.add(UnitDelay(np.zeros((2, 2)), period=0.1), name="z")
    with pytest.raises(av.ShapeError, match="agent count"):
        d.connect(c.y, z.u)
    with pytest.raises(av.ParameterError, match="period"):
        UnitDelay(0.0, period=0.0)
    d = av.Diagram()
    c = d.add(av.blocks.Constant([1.0]), name="c")
    z = d.add(UnitDelay(0.0, period=0.15), name="z")
    d.connect(c.y, z.u)
    with pytest.raises(av.ShapeError, match="multiple of the major step"):
        av.simulate(d, 1.0, dt=0.1)


def test_unit_delay_keeps_integer_and_bool_signals():
    d = av.Diagram()
    c = d.add(av.blocks.Constant(np.array([True, False])), name="c")
    z = d.add(UnitDelay(False, period=0.1), name="z")
    d.connect(c.y, z.u)
    res = av.simulate(d, 0.2, dt=0.1, log=[z.y])
    assert res[z.y].dtype == bool
    assert res[z.y].tolist() == [[False, False], [True, False], [True, False]]


def test_conformance(configured):
    assert check_block(lambda n: configured(UnitDelay(1.0, 0.1), u=(n, 2))).ok
    assert check_block(lambda n: UnitDelay(np.zeros((n, 3)), 0.1)).ok
    assert check_block(lambda n: configured(ZeroOrderHold(0.1), u=(n, 3))).ok
