"""av.linearize against independent truth: central finite differences of
the NumPy engine's own functions (core.engine.Engine with xp=numpy: no JAX,
no perturbation machinery; an input perturbation is made by changing the
Constant that drives the port), closed forms of small diagrams, the
simulator's own runs for a sampled model, and the errors for bad names."""

import os

import numpy as np
import pytest

import avblocks as av
from avblocks.core.engine import Engine
from avblocks.core.errors import CompileError, ParameterError, WiringError

from ._diagrams import formation

if os.environ.get("CI"):
    import jax  # noqa: F401  (in CI the jax extra is installed: never skip)
else:
    pytest.importorskip("jax")
pytestmark = pytest.mark.jax


def numpy_derivative(d, states, constants=None, outputs=(), t=0.0):
    """``(dx/dt, y)`` of ``d`` by the NumPy engine: ``states`` and the
    Constants' values ``constants`` given as ``{"block.name": array}``."""
    cd = d.build()
    for path, v in (constants or {}).items():
        cd.set_param(path, v)
    eng = Engine(cd, 0.01, np)
    X = []
    for name, b in zip(cd.names, cd.blocks):
        x = b.initial_state()
        for k, v in states.items():
            bp, _, nm = k.rpartition(".")
            if bp == name:
                x[nm] = np.asarray(v, float)
        X.append(x)
    Y = eng.all_outputs(t, X, [dict() for _ in cd.blocks])
    K = eng.derivs(t, X, Y)
    pos = {i: j for j, i in enumerate(eng.cont)}
    f = np.concatenate([np.ravel(K[pos[i]][nm]) for i, nm, *_ in eng.layout])
    y = np.concatenate([np.ravel(Y[cd.index(p.rpartition(".")[0])][p.rpartition(".")[2]])
                        for p in outputs]) if outputs else np.zeros(0)
    return f, y


def central_jacobian(fun, x0, h):
    """Columns ``(fun(x0 + h e_j) - fun(x0 - h e_j)) / 2h`` of a vector function."""
    x0 = np.asarray(x0, float)
    cols = []
    for j in range(x0.size):
        e = np.zeros_like(x0)
        e.flat[j] = h
        cols.append((np.concatenate(fun(x0 + e)) - np.concatenate(fun(x0 - e))) / (2 * h))
    return np.stack(cols, axis=-1)


def check_against_differences(d, state, constant, outputs, x, c, h=1e-6, tol=2e-7):
    """A, B, C, D of av.linearize equal central differences of the NumPy
    engine (one continuous state ``state``, inputs driven by the Constant
    ``constant``'s value ``c``)."""
    block = constant.rpartition(".")[0]
    readers = [f"{n}.{p}" for n, b in zip(d.build().names, d.build().blocks)
               for p in b.input_ports
               if d.build().sources[d.build().index(n)][p][0] == d.build().index(block)]
    m = av.linearize(d, at={state: x}, inputs=readers, outputs=outputs,
                     params={constant: c})
    nx = np.size(x)

    def fx(v):
        return numpy_derivative(d, {state: v.reshape(np.shape(x))}, {constant: c}, outputs)

    def fu(v):
        return numpy_derivative(d, {state: x}, {constant: v.reshape(np.shape(c))}, outputs)

    jx = central_jacobian(fx, np.asarray(x, float), h)
    ju = central_jacobian(fu, np.asarray(c, float), h)
    np.testing.assert_allclose(m.A, jx[:nx], rtol=tol, atol=tol)
    np.testing.assert_allclose(m.C, jx[nx:], rtol=tol, atol=tol)
    np.testing.assert_allclose(m.B, ju[:nx], rtol=tol, atol=tol)
    np.testing.assert_allclose(m.D, ju[nx:], rtol=tol, atol=tol)
    f0, y0 = numpy_derivative(d, {state: x}, {constant: c}, outputs)
    np.testing.assert_allclose(m.f0, f0, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(m.y0, y0, rtol=1e-12, atol=1e-12)
    return m


def test_formation_off_its_steady_state_equals_finite_differences_of_the_numpy_engine():
    # a perturbed formation, a leader turning: nothing is at an equilibrium
    rng = np.random.default_rng(5)
    d = formation()
    pose = d["fleet"].block.initial_state()["pose"] + rng.normal(0, 0.2, (4, 3))
    m = check_against_differences(d, "fleet.pose", "lead.value", ["form.error", "form.cmd"],
                                  pose, np.tile([0.6, 0.3], (4, 1)))
    assert m.states[:3] == ["fleet.pose[0].x", "fleet.pose[0].y", "fleet.pose[0].theta"]
    assert m.inputs[:2] == ["form.cmd_in[0].v", "form.cmd_in[0].omega"]
    assert m.outputs[:2] == ["form.error[0].l", "form.error[0].alpha"]
    assert m.outputs[8:10] == ["form.cmd[0].v", "form.cmd[0].omega"]
    assert m.dt == 0 and m.continuous


def test_quadrotor_tilted_and_spinning_equals_finite_differences():
    d = av.Diagram()
    q = d.add(av.vehicles.Quadrotor(np.zeros((2, 3)), mass=[0.5, 0.8],
                                    inertia=(0.003, 0.004, 0.005), drag=0.1), name="quad")
    w = d.add(av.blocks.Constant(np.zeros((2, 4))), name="w")
    d.connect(w.y, q.wrench)
    rng = np.random.default_rng(1)
    att = rng.normal(size=(2, 4))
    att /= np.linalg.norm(att, axis=1, keepdims=True)
    x = {"quad.position": rng.normal(size=(2, 3)), "quad.velocity": rng.normal(size=(2, 3)),
         "quad.attitude": 1.1 * att, "quad.rates": rng.normal(size=(2, 3))}
    # the continuous states are four arrays: compare block by block
    m = av.linearize(d, at=x, inputs=["quad.wrench"], outputs=["quad.pose"],
                     params={"w.value": [[6.0, 0.01, -0.02, 0.003], [9.0, 0, 0.01, 0]]})
    names = ["quad.position", "quad.velocity", "quad.attitude", "quad.rates"]
    x0 = np.concatenate([np.ravel(x[k]) for k in names])
    c = np.array([[6.0, 0.01, -0.02, 0.003], [9.0, 0, 0.01, 0]])

    def split(v):
        out, a = {}, 0
        for k in names:
            n = np.size(x[k])
            out[k] = v[a:a + n].reshape(np.shape(x[k]))
            a += n
        return out

    jx = central_jacobian(lambda v: numpy_derivative(d, split(v), {"w.value": c},
                                                     ["quad.pose"]), x0, 1e-6)
    ju = central_jacobian(lambda v: numpy_derivative(d, x, {"w.value": v.reshape(2, 4)},
                                                     ["quad.pose"]), c.ravel(), 1e-6)
    n = x0.size
    np.testing.assert_allclose(m.A, jx[:n], rtol=2e-7, atol=2e-7)
    np.testing.assert_allclose(m.C, jx[n:], rtol=2e-7, atol=2e-7)
    np.testing.assert_allclose(m.B, ju[:n], rtol=2e-7, atol=2e-7)
    np.testing.assert_allclose(m.D, ju[n:], rtol=2e-7, atol=2e-7)
    assert m.state("quad.attitude") == slice(12, 20)
    assert m.states[12:14] == ["quad.attitude[0].w", "quad.attitude[0].x"]


def test_a_perturbation_enters_only_the_named_port():
    # one signal, two readers: y = x1 (integrator fed by -x1 + c), and a
    # second integrator reading the same constant. A perturbation at s.u1
    # moves only the first.
    d = av.Diagram()
    c = d.add(av.blocks.Constant([[0.0]]), name="c")
    x1 = d.add(av.blocks.Integrator([[0.0]]), name="x1")
    x2 = d.add(av.blocks.Integrator([[0.0]]), name="x2")
    g = d.add(av.blocks.Gain(-3.0), name="g")
    s = d.add(av.blocks.Sum("++"), name="s")
    d.connect(x1.y, g.u)
    d.connect(g.y, s.u0)
    d.connect(c.y, s.u1)
    d.connect(s.y, x1.u)
    d.connect(c.y, x2.u)
    m = av.linearize(d, inputs=["s.u1"], outputs=["s.y"])
    np.testing.assert_array_equal(m.A, [[-3.0, 0.0], [0.0, 0.0]])
    np.testing.assert_array_equal(m.B, [[1.0], [0.0]])
    np.testing.assert_array_equal(m.C, [[-3.0, 0.0]])
    np.testing.assert_array_equal(m.D, [[1.0]])
    # an operating value of the perturbation: s.y = -3 x1 + c + u0
    m = av.linearize(d, at={"s.u1": [[2.0]], "x1.x": [[0.5]]}, inputs=["s.u1"],
                     outputs=["s.y"])
    np.testing.assert_allclose(m.y0, [0.5])
    np.testing.assert_allclose(m.f0, [0.5, 0.0])


def test_a_subsystem_input_perturbs_every_port_it_feeds():
    d = av.Diagram()
    fleet = d.add(av.vehicles.velocity_controlled_quadrotor(
        av.vehicles.Quadrotor(np.array([[0.0, 0.0, 1.0]]))), name="fleet")
    v = d.add(av.blocks.Constant(np.zeros((1, 3))), name="v")
    d.connect(v.y, fleet.velocity)
    m = av.linearize(d, inputs=["fleet.velocity"], outputs=["fleet.position"])
    assert m.inputs == ["fleet.velocity[0].x", "fleet.velocity[0].y", "fleet.velocity[0].z"]
    # same as perturbing the Constant that drives it: central differences
    def f(c):
        return numpy_derivative(d, {}, {"v.value": c.reshape(1, 3)}, ["fleet.quad.position"])
    ju = central_jacobian(f, np.zeros(3), 1e-6)
    np.testing.assert_allclose(m.B, ju[:len(m.states)], atol=2e-7)
    np.testing.assert_allclose(m.D, ju[len(m.states):], atol=2e-7)
    # hover with the cascade's thrust feed-forward: the open-loop model is stable
    assert np.all(m.poles().real < 1e-9)


def test_a_sampled_controller_gives_the_sampled_map_of_the_simulator():
    # plant dx/dt = -a x + u (continuous), controller u = -k x every T (ZOH)
    a, k, T = 0.8, 1.5, 0.2
    d = av.Diagram()
    x = d.add(av.blocks.Integrator([[1.0]]), name="x")
    g = d.add(av.blocks.Gain(-a), name="g")
    s = d.add(av.blocks.Sum("++"), name="s")
    ctl = d.add(av.blocks.Function(lambda t, y, xp: -k * y, inputs={"y": (1, 1)},
                                   outputs={"u": (1, 1)}, period=T), name="ctl")
    d.connect(x.y, g.u)
    d.connect(x.y, ctl.y)
    d.connect(g.y, s.u0)
    d.connect(ctl.u, s.u1)
    d.connect(s.y, x.u)
    m = av.linearize(d, inputs=["s.u1"], outputs=["x.y"], dt=T / 20)
    assert m.dt == pytest.approx(T) and not m.continuous
    # closed form (Franklin, Powell & Workman, ch. 4): zero-order-hold map;
    # a perturbation at s.u1 is held over the period like the controller's output
    ead = np.exp(-a * T)
    exact = ead - k * (1 - ead) / a
    assert abs(m.A[0, 0] - exact) < 1e-9          # RK4 with T/20: O(dt^4)
    assert abs(m.B[0, 0] - (1 - ead) / a) < 1e-9
    np.testing.assert_array_equal(m.C, [[1.0]])
    np.testing.assert_array_equal(m.D, [[0.0]])
    # and the simulator's own run over one period, by central differences
    def run(x0):
        res = av.simulate(d, T, dt=T / 20, x0={"x.x": [[x0]]}, log=[x.y])
        return res.final_state["x.x"][0, 0]
    fd = (run(1.0 + 1e-4) - run(1.0 - 1e-4)) / 2e-4
    assert abs(m.A[0, 0] - fd) < 1e-9
    # the continuous model asked for: the controller taken as transparent
    mc = av.linearize(d, outputs=["x.y"], kind="continuous")
    np.testing.assert_allclose(mc.A, [[-a - k]])


def test_an_operating_point_from_a_run():
    # a perturbed formation run to its steady state: linearising at the run's
    # final state is linearising at {"fleet.pose": its last pose}
    d = formation()
    pose = d["fleet"].block.initial_state()["pose"]
    pose[1:, :2] += 0.3
    res = av.simulate(d, 12.0, dt=0.01, x0={"fleet.pose": pose}, log=["fleet.pose"])
    lin = av.analysis.Linearizer(d)
    m1 = lin(at=res)
    m2 = lin(at={"fleet.pose": res["fleet.pose"][-1]})
    np.testing.assert_array_equal(m1.A, m2.A)
    np.testing.assert_array_equal(m1.x0, res["fleet.pose"][-1].ravel())


def test_python_control_names_and_round_trip():
    control = pytest.importorskip("control") if not os.environ.get("CI") else \
        __import__("control")
    d = formation()
    m = av.linearize(d, inputs=["form.cmd_in"], outputs=["form.error"])
    sys = m.to_control("formation")
    assert sys.state_labels[3] == "fleet/pose[1]/x"
    assert sys.input_labels[0] == "form/cmd_in[0]/v"
    assert sys.output_labels[-1] == "form/error[3]/alpha"
    np.testing.assert_allclose(np.sort_complex(control.poles(sys)),
                               np.sort_complex(m.poles()), atol=1e-12)
    np.testing.assert_array_equal(sys.A, m.A)


def test_names_that_do_not_exist_are_errors_naming_what_is_there():
    d = formation()
    with pytest.raises(WiringError, match="no such block") as e:
        av.linearize(d, inputs=["frm.cmd_in"])
    assert "form.cmd_in" in str(e.value)
    with pytest.raises(WiringError, match="no such input port") as e:
        av.linearize(d, inputs=["form.cmd_inn"])
    assert "cmd_in" in str(e.value)
    with pytest.raises(WiringError, match="an output port cannot be a linear model input")\
            as e:
        av.linearize(d, inputs=["lead.y"])
    assert "form.cmd_in" in str(e.value)          # it names the port to use
    with pytest.raises(WiringError, match="unknown linear model output"):
        av.linearize(d, outputs=["form.cmd_in"])
    with pytest.raises(ParameterError, match="no state and no input") as e:
        av.linearize(d, at={"fleet.poze": np.zeros((4, 3))})
    assert "fleet.pose" in str(e.value)
    with pytest.raises(ParameterError, match="not among the model's inputs"):
        av.linearize(d, at={"form.cmd_in": np.zeros((4, 2))})
    with pytest.raises(ParameterError, match="wrong shape"):
        av.linearize(d, at={"fleet.pose": np.zeros((3, 3))})
    with pytest.raises(ParameterError, match="unknown kind"):
        av.linearize(d, kind="discrete")
    with pytest.raises(ParameterError, match="no such numeric parameter"):
        av.linearize(d, params={"form.k": 1.0})
    with pytest.raises(TypeError):
        av.linearize(d, input=["form.cmd_in"])      # unknown keyword


def test_blocks_that_cannot_be_traced_are_named():
    class Impure(av.Block):
        traceable = False

        def __init__(self):
            super().__init__()
            self.declare_input("u", (1, 1))
            self.declare_output("y", (1, 1))

        def output(self, t, x, u, xp):
            return {"y": u["u"]}

    d = av.Diagram()
    x = d.add(av.blocks.Integrator([[0.0]]), name="x")
    p = d.add(Impure(), name="impure")
    d.connect(x.y, p.u)
    d.connect(p.y, x.u)
    with pytest.raises(CompileError, match="impure"):
        av.linearize(d)


def test_a_point_where_the_model_is_not_finite_is_an_error():
    d = formation()
    pose = d["fleet"].block.initial_state()["pose"]
    pose[1, :2] = pose[0, :2] - 0.1 * np.array([np.cos(pose[1, 2]), np.sin(pose[1, 2])])
    with pytest.raises(av.AvError, match="not finite"):
        av.linearize(d, at={"fleet.pose": pose})
