"""Fixed-step solvers: convergence order against an exact solution; the
variable-step path against a direct solve_ivp of the same equations."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import avblocks as av


class Oscillator(av.Block):
    """x'' = -w^2 x as a first-order system, with a time-varying forcing."""

    def __init__(self, x0, w=2.0):
        super().__init__()
        self.w = w
        self.declare_continuous_state("z", x0)
        self.declare_output("y", np.shape(x0))

    def output(self, t, x, u, xp):
        return {"y": x["z"]}

    def derivative(self, t, x, u, xp):
        z = x["z"]
        return {"z": xp.stack([z[:, 1], -self.w**2 * z[:, 0] + xp.cos(t)], axis=-1)}


def exact(t, w=2.0):
    # x(0) = 1, v(0) = 0: x = (1 - 1/(w^2-1)) cos(w t) + cos(t)/(w^2-1)
    a = 1.0 / (w**2 - 1)
    return (1 - a) * np.cos(w * t) + a * np.cos(t)


def run(solver, dt, t_final=2.0):
    d = av.Diagram()
    o = d.add(Oscillator(np.array([[1.0, 0.0]])), name="o")
    res = av.simulate(d, t_final, dt=dt, solver=solver, log=[o.y])
    return abs(res[o.y][-1, 0, 0] - exact(t_final))


@pytest.mark.parametrize("solver,order", [("euler", 1), ("rk4", 4)])
def test_convergence_order(solver, order):
    dts = np.array([0.02, 0.01, 0.005, 0.0025]) if solver == "euler" else \
        np.array([0.1, 0.05, 0.025, 0.0125])
    errs = np.array([run(solver, dt) for dt in dts])
    slope = np.polyfit(np.log(dts), np.log(errs), 1)[0]
    assert slope == pytest.approx(order, abs=0.15)


@pytest.mark.parametrize("method", ["RK45", "DOP853", "LSODA"])
def test_variable_step_matches_solve_ivp(method):
    d = av.Diagram()
    o = d.add(Oscillator(np.array([[1.0, 0.0]])), name="o")
    res = av.simulate(d, 3.0, dt=0.1, solver=av.core.Scipy(method, rtol=1e-10, atol=1e-12),
                      log=[o.y])

    def f(t, z):
        return [z[1], -4.0 * z[0] + np.cos(t)]

    ref = solve_ivp(f, (0, 3.0), [1.0, 0.0], method="DOP853", rtol=1e-12, atol=1e-13,
                    t_eval=res.t)
    assert np.allclose(res[o.y][:, 0, :], ref.y.T, atol=1e-7)
    assert np.allclose(res[o.y][:, 0, 0], exact(res.t), atol=1e-7)


def test_solver_by_hand_matches_simulate():
    d = av.Diagram()
    o = d.add(Oscillator(np.array([[1.0, 0.0]])), name="o")
    res = av.simulate(d, 1.0, dt=0.01, log=[o.y])
    sim = av.Simulator(d, dt=0.01)
    sim.init()
    for _ in range(100):
        sim.step()
    assert sim.t == pytest.approx(1.0)
    assert np.array_equal(sim.value(o.y), res[o.y][-1])


def test_unknown_solver_is_rejected():
    d = av.Diagram()
    d.add(Oscillator(np.array([[1.0, 0.0]])), name="o")
    with pytest.raises(av.ParameterError, match="unknown solver"):
        av.simulate(d, 1.0, solver="rk5")


def test_variable_step_restarts_at_sample_hits_only():
    # a clock sampled every 0.25 s by a zero-order hold drives an integrator:
    # x(t) = integral of the staircase floor(t / 0.25) * 0.25, exact
    d = av.Diagram()
    clk = d.add(av.blocks.Clock(), name="clk")
    f = d.add(av.blocks.Function(lambda t, u: u.reshape(1, 1), inputs={"u": ()},
                                 outputs={"y": (1, 1)}), name="f")
    zoh = d.add(av.blocks.ZeroOrderHold(0.25), name="zoh")
    i = d.add(av.blocks.Integrator(np.zeros((1, 1))), name="i")
    d.connect(clk.y, f.u)
    d.connect(f.y, zoh.u)
    d.connect(zoh.y, i.u)
    solver = av.core.Scipy("RK45", rtol=1e-10, atol=1e-12)
    res = av.simulate(d, 2.0, dt=0.05, solver=solver, log=[i.y])
    t = res.t
    k = np.floor(t / 0.25 + 1e-9)
    exact = 0.25 * (0.25 * k * (k - 1) / 2) + (t - 0.25 * k) * 0.25 * k
    assert np.allclose(res[i.y][:, 0, 0], exact, atol=1e-9)
    # one adaptive solve per 0.25 s segment, not per 0.05 s major step
    per_step = av.core.Scipy("RK45", rtol=1e-10, atol=1e-12)
    sim = av.Simulator(d, 0.05, per_step)   # stepping by hand: no span
    sim.init()
    for _ in range(40):
        sim.step()
    assert np.allclose(sim.value(i.y)[0, 0], exact[-1], atol=1e-9)
    assert solver.nfev < per_step.nfev
