"""The front end: simulate()/compile() pick an engine by name through one
contract, load engines only when asked, and Results/Diagram conveniences find
the drawing layer through a named backend."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

import avblocks as av
from avblocks.core import frontend, plotting


def _ramp():
    d = av.Diagram()
    c = d.add(av.blocks.Constant([[2.0]]), name="c")
    i = d.add(av.blocks.Integrator([[0.0]]), name="i")
    d.connect(c.y, i.u)
    return d, i


def test_a_registered_engine_gets_the_contract_arguments_and_its_results_come_back():
    seen = {}
    d, i = _ramp()
    ref = av.simulate(d, 1.0, dt=0.1, log=[i.y])

    def fake(diagram, t_final, dt, solver, **kw):
        seen.update(diagram=diagram, t_final=t_final, dt=dt, solver=solver, **kw)
        return ref

    frontend.register_engine("fake", fake)
    try:
        out = av.simulate(d, 3.0, dt=0.5, solver="euler", log=[i.y], seed=7,
                          backend="fake", gain=2)
    finally:
        frontend.ENGINES.pop("fake")
        frontend._loaded.pop("fake")
    assert out is ref
    assert seen["diagram"] is d and (seen["t_final"], seen["dt"], seen["solver"]) == \
        (3.0, 0.5, "euler")
    assert {k: seen[k] for k in ("seed", "log_every", "realtime", "params", "x0", "gain")} \
        == {"seed": 7, "log_every": None, "realtime": None, "params": None, "x0": None,
            "gain": 2}
    assert set(seen) >= {"progress", "check_finite", "max_log_bytes", "log"}


def test_numpy_engine_through_the_front_end_integrates_a_constant():
    d, i = _ramp()
    res = av.simulate(d, 1.0, dt=0.1, log=[i.y])
    # x' = 2, x(0) = 0: x(t) = 2 t at every logged time
    np.testing.assert_allclose(res[i.y][:, 0, 0], 2.0 * res.t, atol=1e-12)
    assert res.final_state["i.x"][0, 0] == pytest.approx(2.0)


def test_unknown_backends_are_refused_with_the_choices():
    d, _ = _ramp()
    with pytest.raises(av.ParameterError, match="unknown backend") as e:
        av.simulate(d, 1.0, backend="torch")
    assert "'numpy'" in str(e.value) and "'jax'" in str(e.value)
    with pytest.raises(av.ParameterError, match="unknown compiled backend"):
        av.compile(d, 1.0, backend="numpy")
    with pytest.raises(av.ParameterError, match="live=True"):
        av.simulate(d, 1.0, backend="jax", live=True)


def test_engines_are_loaded_only_when_a_run_asks_for_them():
    code = (
        "import sys, numpy as np, avblocks as av\n"
        "d = av.Diagram(); c = d.add(av.blocks.Constant([[1.0]]), name='c')\n"
        "i = d.add(av.blocks.Integrator([[0.0]]), name='i'); d.connect(c.y, i.u)\n"
        "av.simulate(d, 0.1, dt=0.1, progress=False)\n"
        "print(sorted(m for m in ('avblocks.viz', 'avblocks.viz.live', "
        "'avblocks.core.compiled.entry', 'avblocks.scenarios') if m in sys.modules))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == "[]"


def test_results_plot_goes_through_the_named_backend():
    calls = []

    class Backend:
        @staticmethod
        def plot_trajectories(res, ax=None, **kw):
            calls.append(("paths", res, ax, kw))
            return "fig"

        @staticmethod
        def plot_signals(res, signals, **kw):
            calls.append(("signals", res, signals, kw))
            return "fig2"

    d, i = _ramp()
    res = av.simulate(d, 0.2, dt=0.1, log=[i.y])
    plotting.register_backend("test-backend", Backend)
    old = plotting.options["backend"]
    plotting.options["backend"] = "test-backend"
    try:
        assert res.plot(color="k") == "fig"
        assert res.plot("i.y") == "fig2"
    finally:
        plotting.options["backend"] = old
        plotting._BACKENDS.pop("test-backend")
    assert calls == [("paths", res, None, {"color": "k"}), ("signals", res, ["i.y"], {})]
    with pytest.raises(av.AvError, match="plotting backend"):
        plotting.get_backend("no_such_module_for_plots")
