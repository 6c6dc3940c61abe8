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


def _kept(run):
    """{input key: device array} the runner keeps for its next call."""
    return {k: dev for k, (_, dev) in run._kept.items()}


@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_unchanged_inputs_stay_on_the_device(dtype):
    # each call against the NumPy engine's run of the same values (float32:
    # to its rounding); the device copies of unchanged parameters and
    # initial states are the same arrays from one call to the next, and a
    # new value (set_parameter, set_initial) is placed afresh
    d, gain, integ, i = _diagram()
    run = av.compile(d, 1.0, dt=0.1, solver="euler", log=[i.y], dtype=dtype)
    tol = 1e-12 if dtype == "float64" else 1e-5

    def check():
        ref = av.simulate(d, 1.0, dt=0.1, solver="euler", log=[i.y], progress=False)
        np.testing.assert_allclose(run()[i.y], ref[i.y], rtol=0, atol=tol)

    check()                                       # compiles
    check()                                       # places and keeps
    kept = _kept(run)
    assert {("theta", "g.k"), ("x0", 2, "x")} <= set(kept)
    assert kept[("theta", "g.k")].dtype == np.dtype(dtype)
    check()
    assert all(_kept(run)[k] is v for k, v in kept.items())
    gain.set_parameter("k", 4.0)
    integ.set_initial("x", [[-1.0]])
    check()
    now = _kept(run)
    assert now[("theta", "g.k")] is not kept[("theta", "g.k")]
    assert now[("x0", 2, "x")] is not kept[("x0", 2, "x")]
    assert float(now[("theta", "g.k")]) == 4.0
    assert now[("theta", "c.value")] is kept[("theta", "c.value")]
    assert run()[i.y][-1, 0, 0] == pytest.approx(-1.0 + 4.0 * 1.0)
    run.keep_inputs = False
    assert _kept(run) == {}
    check()
    assert _kept(run) == {}


def test_a_callers_own_arrays_are_read_at_every_call():
    # an x0 array the caller may write between calls is never kept
    d, _, _, i = _diagram()
    run = av.compile(d, 1.0, dt=0.1, solver="euler", log=[i.y])
    start = np.array([[0.0]])
    for value in (0.0, 2.0, -3.0):
        start[0, 0] = value
        assert run(x0={"i.x": start})[i.y][-1, 0, 0] == pytest.approx(value + 2.0)
    assert ("x0", 2, "x") not in run._kept


def test_block_values_are_frozen_and_replaced_whole():
    # parameters and declared initial states are read-only C-ordered arrays
    # (a compiled runner keeps device copies of them by identity); a new value
    # replaces the array, a copy handed out can be written
    d, gain, integ, i = _diagram()
    with pytest.raises(ValueError, match="read-only"):
        gain.k[...] = 3.0
    with pytest.raises(ValueError, match="read-only"):
        integ._init["x"][0, 0] = 1.0
    old = gain.k
    gain.set_parameter("k", 3.0)
    assert gain.k is not old and float(old) == 2.0 and float(gain.k) == 3.0
    copy = gain.get_parameter("k")
    copy[...] = 9.0
    assert float(gain.k) == 3.0
    state = integ.initial_state()
    state["x"][0, 0] = 7.0
    assert integ._init["x"][0, 0] == 0.5
    law = av.controllers.Flocking(1000, 7.0, r=8.4, gamma=True, target=[1.0, 2.0],
                                  target_velocity=[2.0, 1.0])
    for name in ("target", "target_velocity"):
        a = getattr(law, name)
        assert a.flags.c_contiguous and not a.flags.writeable and a.flags.owndata
        np.testing.assert_array_equal(a[0], a[-1])
