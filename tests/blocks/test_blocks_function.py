import numpy as np
import pytest

import avblocks as av
from avblocks.blocks import Function, Integrator
from avblocks.core.check import check_block


def _decay(fn_block, x0, t_final=2.0, dt=0.01, port="dx"):
    d = av.Diagram()
    i = d.add(Integrator(x0), name="i")
    f = d.add(fn_block, name="f")
    d.connect(i.y, f.port(next(iter(fn_block.input_ports))))
    d.connect(f.port(port), i.u)
    return av.simulate(d, t_final, dt=dt, log=[i.y]), i


def test_function_in_a_closed_loop_gives_exponential_decay():
    x0 = np.array([[1.0, -2.0], [0.5, 3.0]])
    res, i = _decay(Function(lambda t, x: -x, inputs={"x": (2, 2)},
                             outputs={"dx": (2, 2)}), x0)
    truth = x0[None] * np.exp(-res.t)[:, None, None]
    np.testing.assert_allclose(res[i.y], truth, rtol=0, atol=1e-9)


def test_function_gets_xp_and_returns_dicts_and_infers_shapes():
    seen = []

    def fn(t, x, xp):
        seen.append(xp)
        return {"dx": -2.0 * x, "norm": xp.sum(x * x, axis=-1)}

    x0 = np.array([1.0, 2.0, 3.0])
    f = Function(fn, inputs={"x": None}, outputs={"dx": None, "norm": None})
    res, i = _decay(f, x0, t_final=1.0)
    assert seen and all(s is np for s in seen)
    assert f.output_ports["norm"].shape == () and f.output_ports["dx"].shape == (3,)
    np.testing.assert_allclose(res[i.y], x0 * np.exp(-2 * res.t)[:, None], atol=1e-8)


def test_function_without_feedthrough_is_a_one_step_delay():
    # x_{k+1} = x_k + dt * f(x_{k-1}) would be a different scheme; here check the
    # delay directly: f reads a clock, its output lags by one major step.
    d = av.Diagram()
    c = d.add(av.blocks.Clock(), name="c")
    f = d.add(Function(lambda t, u: 2 * u, inputs={"u": ()}, outputs={"y": ()},
                       feedthrough=False, initial={"y": -1.0}), name="f")
    d.connect(c.y, f.u)
    res = av.simulate(d, 0.5, dt=0.1, log=[f.y])
    np.testing.assert_allclose(res[f.y], np.r_[-1.0, 2 * res.t[:-1]], atol=1e-12)


def test_function_without_feedthrough_breaks_a_loop_and_with_it_does_not():
    def build(ft):
        d = av.Diagram()
        f = d.add(Function(lambda t, a: a + 1, inputs={"a": (1,)}, outputs={"b": (1,)},
                           feedthrough=ft, period=0.1), name="f")
        d.connect(f.b, f.a)
        return d, f
    d, _ = build(True)
    with pytest.raises(av.AlgebraicLoopError):
        d.build()
    d, f = build(False)
    res = av.simulate(d, 0.5, dt=0.1, log=[f.b])
    np.testing.assert_allclose(res[f.b][:, 0], np.arange(6.0))


def test_periodic_function_holds_its_output():
    d = av.Diagram()
    c = d.add(av.blocks.Clock(), name="c")
    f = d.add(Function(lambda t, u: u, inputs={"u": ()}, outputs={"y": ()},
                       period=0.2), name="f")
    d.connect(c.y, f.u)
    res = av.simulate(d, 1.0, dt=0.1, log=[f.y])
    np.testing.assert_allclose(res[f.y], np.floor(res.t / 0.2 + 1e-9) * 0.2, atol=1e-12)


def test_function_validation():
    with pytest.raises(av.ParameterError, match="callable"):
        Function(3, inputs={}, outputs={"y": ()})
    with pytest.raises(av.ParameterError, match="cannot be called"):
        Function(lambda t, a: a, inputs={"b": ()}, outputs={"y": ()})
    with pytest.raises(av.ParameterError, match="identifiers"):
        Function(lambda t, xp: 0, inputs={"xp": ()}, outputs={"y": ()})
    with pytest.raises(av.ParameterError):
        Function(lambda t: 0, outputs={})
    with pytest.raises(av.ParameterError, match="shape"):
        Function(lambda t: 0, outputs={"y": "big"})
    with pytest.raises(TypeError):
        Function(lambda t: 0, outputs={"y": ()}, feedthru=False)
    with pytest.raises(av.ParameterError, match="initial"):
        Function(lambda t: 0, outputs={"y": ()}, initial={"y": 1.0})


def test_function_returning_wrong_ports_fails_in_words():
    d = av.Diagram()
    f = d.add(Function(lambda t: {"z": np.zeros(2)}, outputs={"y": (2,)}), name="f")
    with pytest.raises(av.SimulationError, match="other outputs") as e:
        av.simulate(d, 0.1, dt=0.1, log=[f.y])
    assert "['z']" in str(e.value)
    d = av.Diagram()
    f = d.add(Function(lambda t: np.zeros(3), outputs={"y": (2,)}), name="f")
    with pytest.raises(av.ShapeError, match="wrong shape"):
        av.simulate(d, 0.1, dt=0.1, log=[f.y])


def test_conformance():
    assert check_block(lambda n: Function(
        lambda t, pose, xp: xp.stack([xp.cos(pose[:, 2]), 0 * pose[:, 0]], axis=-1),
        inputs={"pose": (n, 3)}, outputs={"cmd": (n, 2)})).ok
    assert check_block(lambda n: Function(
        lambda t, pose: pose[:, :2], inputs={"pose": (n, 3)}, outputs={"p": (n, 2)},
        feedthrough=False, period=0.1)).ok
