import numpy as np
import pytest

import avblocks as av
from avblocks.blocks import DeadZone, RateLimiter, Saturation
from avblocks.core.check import check_block


def _run(src_block, blk, t_final, dt, **kw):
    d = av.Diagram()
    s = d.add(src_block, name="s")
    b = d.add(blk, name="b")
    d.connect(s.y, b.u)
    return av.simulate(d, t_final, dt=dt, log=[b.y, s.y], **kw), b, s


def test_saturation_exact_values():
    u = np.array([[-3.0, -1.0], [-0.5, 0.0], [0.99, 2.5]])
    res, b, _ = _run(av.blocks.Constant(u), Saturation(-1.0, 1.0), 0.0, 0.1)
    np.testing.assert_array_equal(res[b.y][0], [[-1, -1], [-0.5, 0], [0.99, 1]])


def test_saturation_per_component_and_one_sided(configured):
    u = np.array([[5.0, -5.0], [-5.0, 5.0]])
    blk = configured(Saturation([0.0, -np.inf], [1.0, 2.0]), u=(2, 2))
    y = blk.output(0.0, {}, {"u": u}, np)["y"]
    np.testing.assert_array_equal(y, [[1.0, -5.0], [0.0, 2.0]])


def test_deadzone_exact_values():
    u = np.array([-3.0, -1.0, -0.2, 0.0, 0.4, 0.5, 2.0])
    res, b, _ = _run(av.blocks.Constant(u), DeadZone(-1.0, 0.5), 0.0, 0.1)
    np.testing.assert_allclose(res[b.y][0], [-2.0, 0, 0, 0, 0, 0, 1.5], atol=0, rtol=0)


@pytest.mark.parametrize("cls", [Saturation, DeadZone])
def test_bounds_validated(cls):
    with pytest.raises(av.ParameterError, match="lower must not exceed upper"):
        cls(1.0, -1.0)
    with pytest.raises(av.ParameterError, match="NaN"):
        cls(np.nan, 1.0)


def test_bounds_that_do_not_broadcast_raise_shape_error():
    d = av.Diagram()
    c = d.add(av.blocks.Constant(np.zeros((4, 2))), name="c")
    s = d.add(Saturation([0, 0, 0], [1, 1, 1]), name="sat")
    d.connect(c.y, s.u)
    with pytest.raises(av.ShapeError) as e:
        d.build()
    assert e.value.port == "u" and e.value.found == (4, 2)
    assert "block 'sat'" in str(e.value)  # named as in the diagram


def test_rate_limiter_periodic_ramp_slopes():
    # a step 0 -> 1 at t=0.5 then 1 -> -1 at t=2; rise at 2/s, fall at 0.5/s
    class Steps(av.Block):
        def __init__(self):
            super().__init__()
            self.declare_output("y", (1,))

        def output(self, t, x, u, xp):
            return {"y": xp.asarray([np.where(t < 0.5, 0.0, np.where(t < 2.0, 1.0, -1.0))])}

    res, b, _ = _run(Steps(), RateLimiter(2.0, -0.5, period=0.1), 4.0, 0.05)
    t, y = res.t, res[b.y][:, 0]
    # held between hits at 0.1 s: the value at t is the sample at floor(t / 0.1)
    tk = np.floor(t / 0.1 + 1e-9) * 0.1
    # the sample at 0.5 s already sees the step and moves by rate * 0.1
    up = np.clip(2.0 * (tk - 0.5 + 0.1), 0.0, 1.0)
    down = np.clip(1.0 - 0.5 * (tk - 2.0 + 0.1), -1.0, 1.0)
    truth = np.where(tk < 2.0 - 1e-9, up, down)
    np.testing.assert_allclose(y, truth, atol=1e-12)
    # slopes measured on the ramps
    assert np.diff(y[(t > 0.6) & (t < 0.95)][::2]).mean() == pytest.approx(0.2)
    assert np.diff(y[(t > 2.1) & (t < 3.5)][::2]).mean() == pytest.approx(-0.05)


def test_rate_limiter_per_step_first_input_and_per_agent_rates():
    # per major step (no period): dt is the step; two agents with own rates
    src = av.blocks.Step(0.2, before=[3.0, 3.0], after=[4.0, 0.0])
    res, b, _ = _run(src, RateLimiter([1.0, 1.0], [-1.0, -2.0]), 1.0, 0.05)
    t, y = res.t, res[b.y]
    assert y[0].tolist() == [3.0, 3.0]                   # starts at the first input
    since = t - 0.2 + 0.05          # the sample at t = 0.2 already moves by one step
    np.testing.assert_allclose(y[:, 0], np.clip(3.0 + since, 3.0, 4.0), atol=1e-12)
    np.testing.assert_allclose(y[:, 1], np.clip(3.0 - 2.0 * since, 0.0, 3.0), atol=1e-12)


def test_rate_limiter_initial_value_and_slow_signal_passes():
    res, b, s = _run(av.blocks.Sine(0.1, 0.5, agents=False),
                     RateLimiter(10.0, initial=0.0, period=0.05), 2.0, 0.05)
    # |du/dt| <= 0.1 * 2 pi * 0.5 < 10: the output is the input
    np.testing.assert_allclose(res[b.y], res[s.y], atol=1e-12)
    res, b, _ = _run(av.blocks.Constant([2.0]), RateLimiter(1.0, initial=[5.0],
                                                            period=0.5), 3.0, 0.5)
    np.testing.assert_allclose(res[b.y][:, 0], [5.0, 4.5, 4.0, 3.5, 3.0, 2.5, 2.0])


def test_rate_limiter_rejects_bad_rates():
    with pytest.raises(av.ParameterError, match="falling"):
        RateLimiter(1.0, 1.0)
    with pytest.raises(av.ParameterError, match="rising"):
        RateLimiter(-1.0)
    with pytest.raises(TypeError):
        RateLimiter(1.0, rate=2.0)


@pytest.mark.parametrize("make, comp", [
    (lambda n: Saturation([-1, 0], [1, 2]), (2,)),
    (lambda n: DeadZone(-0.3, 0.3), (3,)),
    (lambda n: RateLimiter(1.0, initial=0.0, period=0.1), (2,)),
    (lambda n: RateLimiter(np.ones(n)), ()),
])
def test_conformance(make, comp, configured):
    assert check_block(lambda n: configured(make(n), u=(n, *comp))).ok
