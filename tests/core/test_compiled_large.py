"""A large compiled run's results (avblocks.core.compiled.outcome): checked
for NaN/inf on the device (a flag per array comes back) and its final state
read from the device only when asked for; the same values and the same
errors as the host path of a small run."""

import os

import numpy as np
import pytest

import avblocks as av
from avblocks.core.compiled import outcome
from avblocks.core.errors import SimulationError

if os.environ.get("CI"):
    import jax  # noqa: F401  (in CI the jax extra is installed: never skip)
else:
    pytest.importorskip("jax")
pytestmark = pytest.mark.jax


def ramp(k=1.0, n=64):
    """y = k t per agent (an integrator of a constant k): overflows to inf
    once k t > 1.797e308."""
    d = av.Diagram()
    c = d.add(av.blocks.Constant(np.ones((n, 2))), name="c")
    g = d.add(av.blocks.Gain(k), name="g")
    i = d.add(av.blocks.Integrator(np.zeros((n, 2))), name="i")
    d.connect(c.y, g.u)
    d.connect(g.y, i.u)
    return d


@pytest.fixture
def everything_large(monkeypatch):
    monkeypatch.setattr(outcome, "LARGE_BYTES", 1)


def test_a_large_run_keeps_its_final_state_on_the_device_until_read(everything_large):
    small = av.compile(ramp(), 1.0, dt=0.1, log=["i.y"], cache=False)
    res = small()
    assert isinstance(res.final_state, outcome.FinalStates)
    assert sorted(res.final_state) == ["i.x"] and len(res.final_state) == 1
    got = res.final_state["i.x"]
    assert isinstance(got, np.ndarray)
    np.testing.assert_allclose(got, np.ones((64, 2)), rtol=0, atol=1e-12)    # y = t at 1
    assert dict(res.final_state.items())["i.x"] is got          # read once, kept
    outcome.LARGE_BYTES = 2**62
    host = small()
    assert isinstance(host.final_state, dict)
    np.testing.assert_array_equal(host.final_state["i.x"], got)
    np.testing.assert_array_equal(host["i.y"], res["i.y"])


def test_a_large_run_reports_nan_as_the_host_check_does(everything_large):
    with pytest.raises(SimulationError, match="NaN or infinite") as e:
        av.simulate(ramp(1e308), 3.0, dt=0.1, log=["i.y"], backend="jax", cache=False)
    assert e.value.block == "i" and e.value.port == "y"
    assert abs(e.value.time - 1.8) < 1e-9                 # 1e308 t passes 1.797e308
    assert e.value.results["i.y"].shape == (31, 64, 2)    # nothing lost
    # not logged: the final state's check names the state
    with pytest.raises(SimulationError, match="state 'x' is NaN or infinite"):
        av.simulate(ramp(1e308), 3.0, dt=0.1, log=["c.y"], backend="jax", cache=False)


def test_device_flags_are_numpys_isfinite():
    import jax.numpy as jnp
    rng = np.random.default_rng(0)
    arrays = [rng.normal(size=(50, 3)) for _ in range(4)] + [np.arange(5)]
    arrays[1][7, 2] = np.nan
    arrays[3][0, 0] = -np.inf
    got = outcome.finite_on_device([jnp.asarray(a) for a in arrays])
    assert got == [bool(np.isfinite(a).all()) for a in arrays[:4]]
