"""A repeated ``Runner`` call reads the blocks' values afresh without
re-validating them, passes the declared initial states without copying them
and shares its run facts between runs: none of it may leak from one call to
the next. Each run is checked against the NumPy engine."""

import os

import numpy as np
import pytest

import avblocks as av

if os.environ.get("CI"):
    import jax  # noqa: F401  (in CI the jax extra is installed: never skip)
else:
    pytest.importorskip("jax")
pytestmark = pytest.mark.jax


def _diagram():
    d = av.Diagram()
    c = d.add(av.blocks.Constant([[1.0]]), name="c")
    gain, integ = av.blocks.Gain(2.0), av.blocks.Integrator([[0.5]])
    g = d.add(gain, name="g")
    i = d.add(integ, name="i")
    d.connect(c.y, g.u)
    d.connect(g.y, i.u)
    return d, gain, integ, i


def test_values_read_afresh_and_overrides_do_not_leak():
    d, gain, integ, i = _diagram()
    run = av.compile(d, 1.0, dt=0.1, solver="euler", log=[i.y])
    init = integ.initial_state()
    first = run()
    # an override of a state and a parameter applies to its call only
    other = run(params={"g.k": 3.0}, x0={"i.x": [[1.0]]}, seed=7)
    assert other[i.y][-1, 0, 0] == pytest.approx(1.0 + 3.0 * 1.0)
    again = run()
    np.testing.assert_array_equal(again[i.y], first[i.y])
    assert first[i.y][-1, 0, 0] == pytest.approx(0.5 + 2.0 * 1.0)
    # a value set on the block between calls is seen, as by the NumPy engine
    gain.set_parameter("k", 4.0)
    ref = av.simulate(d, 1.0, dt=0.1, solver="euler", log=[i.y], progress=False)
    np.testing.assert_allclose(run()[i.y], ref[i.y], rtol=0, atol=1e-12)
    # the declared initial values are untouched by the runs
    for k, v in integ.initial_state().items():
        np.testing.assert_array_equal(v, init[k])


def test_run_facts_per_call():
    d, _, _, i = _diagram()
    run = av.compile(d, 1.0, dt=0.1, solver="euler", log=[i.y], seed=3)
    a, b = run(), run(seed=9, params={"g.k": 1.5})
    assert (a.meta["seed"], b.meta["seed"]) == (3, 9)
    assert "params" not in a.meta and b.meta["params"] == {"g.k": 1.5}
    assert a.meta["compile_time"] >= 0 and b.meta["compile_time"] == 0.0
    assert list(a.meta)[:8] == ["backend", "device", "dtype", "solver", "dt", "seed",
                                "t0", "t_final"]
    assert a.meta["steps"] == 10 and a.meta["t_final"] == pytest.approx(1.0)
    b.meta["steps"] = -1                 # a caller's edit stays in its Results
    assert run().meta["steps"] == 10


class _Shifted(av.blocks.Integrator):
    """An integrator whose own initial_state() starts one above its declared value."""

    def initial_state(self):
        return {k: v + 1.0 for k, v in super().initial_state().items()}


def test_own_initial_state_is_used_as_by_numpy():
    d = av.Diagram()
    c = d.add(av.blocks.Constant([[1.0]]), name="c")
    i = d.add(_Shifted([[0.5]]), name="i")
    d.connect(c.y, i.u)
    ref = av.simulate(d, 1.0, dt=0.1, solver="euler", log=[i.y], progress=False)
    run = av.compile(d, 1.0, dt=0.1, solver="euler", log=[i.y])
    for _ in range(2):
        np.testing.assert_allclose(run()[i.y], ref[i.y], rtol=0, atol=1e-12)
    assert ref[i.y][0, 0, 0] == pytest.approx(1.5)
