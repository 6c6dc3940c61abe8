"""Logging every step computes each step's outputs once: the sample logs the
outputs its step integrates with (counted at run time by a block whose
output calls back to the host), values equal to a run logged every few
steps and to the NumPy engine."""

import os

import numpy as np
import pytest

import avblocks as av

if os.environ.get("CI"):
    import jax  # in CI the jax extra is installed: never skip
else:
    jax = pytest.importorskip("jax")
pytestmark = pytest.mark.jax


class _Counted(av.Block):
    """y = -u, and one host call each time a compiled run evaluates it."""

    def __init__(self, calls):
        super().__init__()
        self.calls = calls
        self.declare_input("u", (2, 2))
        self.declare_output("y", (2, 2))

    def output(self, t, x, u, xp):
        if xp is not np:
            jax.debug.callback(lambda: self.calls.append(1))
        return {"y": -u["u"]}


def _diagram(calls):
    d = av.Diagram()
    f = d.add(av.vehicles.SingleIntegrator(np.array([[1.0, 2.0], [-3.0, 0.5]])), name="f")
    c = d.add(_Counted(calls), name="c")
    d.connect(f.position, c.u)
    d.connect(c.y, f.velocity)
    return d


@pytest.mark.parametrize("solver, per_step", [("euler", 1), ("rk4", 4)])
def test_logging_every_step_evaluates_each_step_once(solver, per_step):
    steps = 10
    calls = []
    r = av.compile(_diagram(calls), steps * 0.1, dt=0.1, solver=solver,
                   log=["c.y", "f.position"], cache=False)
    calls.clear()
    res = r()
    jax.effects_barrier()
    # each step's outputs (logged and integrated with) and its solver's
    # other stages, the sample after the last step. Before, every sample
    # computed its outputs once more than its step (22 calls here with
    # Euler, 52 with RK4), and the run began with the outputs at t0 that
    # step 0 computes again (one call more: 12 and 42)
    assert len(calls) == steps * per_step + 1
    # x' = -x: the log against the exact solution and the NumPy engine
    t = np.asarray(res.t)
    x0 = np.array([[1.0, 2.0], [-3.0, 0.5]])
    p = np.asarray(res["f.position"])
    np.testing.assert_allclose(np.asarray(res["c.y"]), -p, rtol=0, atol=0)
    ref = av.simulate(_diagram([]), steps * 0.1, dt=0.1, solver=solver,
                      log=["c.y", "f.position"])
    np.testing.assert_allclose(p, np.asarray(ref["f.position"]), rtol=1e-13, atol=1e-15)
    if solver == "rk4":
        np.testing.assert_allclose(p, np.exp(-t)[:, None, None] * x0, rtol=1e-6)


def test_every_step_and_every_fifth_step_log_the_same_samples():
    a = av.compile(_diagram([]), 1.0, dt=0.1, log=["c.y"], cache=False)()
    b = av.compile(_diagram([]), 1.0, dt=0.1, log=["c.y"], log_every=5, cache=False)()
    np.testing.assert_array_equal(np.asarray(a["c.y"])[::5], np.asarray(b["c.y"]))
    np.testing.assert_array_equal(np.asarray(a.t)[::5], np.asarray(b.t))
