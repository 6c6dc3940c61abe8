"""What a compiled neighbour search needed is carried through the run (a
running maximum in the scan's carry, out of the Verlet rebuild's
``while_loop`` too) and compared once after it: no host callback in the
program, and an overflow in one run of an ensemble is found (the largest
need over the runs) and raises or re-plans as documented."""

import numpy as np
import pytest

import avblocks as av
from avblocks.core.errors import SimulationError
from avblocks.environment import Neighbors

pytest.importorskip("jax")

N = 60
LOG = ["nb.neighbors"]


def _pulled(**kw):
    """Agents pulled to the origin at rate -g.k (all in one cell when k < 0)."""
    rng = np.random.default_rng(0)
    d = av.Diagram()
    ag = d.add(av.vehicles.SingleIntegrator(rng.uniform(-10, 10, (N, 2))), name="ag")
    g = d.add(av.blocks.Gain(0.0), name="g")
    nb = d.add(Neighbors(N, 4, radius=1.0, input="position", **kw), name="nb")
    d.connect(ag.position, g.u)
    d.connect(g.y, ag.velocity)
    d.connect(ag.position, nb.position)
    return d


@pytest.mark.parametrize("skin", [0.0, 0.3])
def test_the_program_calls_no_host_callback(skin):
    run = av.compile(_pulled(skin=skin), 0.5, dt=0.05, log=LOG)
    run()
    calls = [ln for ln in run._run_exe[1].as_text().splitlines() if "custom-call(" in ln]
    assert not [ln for ln in calls if "callback" in ln.lower()]


@pytest.mark.parametrize("skin", [0.0, 0.3])
def test_one_overflowing_run_of_an_ensemble_raises(skin):
    run = av.compile(_pulled(skin=skin), 3.0, dt=0.05, log=LOG, on_overflow="raise")
    run.ensemble(params={"g.k": [0.0, 0.0]})            # no run converges: fine
    with pytest.raises(SimulationError, match="nb.*(capacity|hits)"):
        run.ensemble(params={"g.k": [0.0, -2.0, 0.0]})  # only run 1 converges


@pytest.mark.parametrize("skin", [0.0, 0.3])
def test_one_overflowing_run_of_an_ensemble_replans_and_equals_numpy(skin):
    d = _pulled(skin=skin)
    run = av.compile(d, 3.0, dt=0.05, log=LOG)
    ks = [0.0, -2.0]
    with pytest.warns(RuntimeWarning, match="re-planned"):
        res = run.ensemble(params={"g.k": ks})
    for r, k in enumerate(ks):
        ref = av.simulate(d, 3.0, dt=0.05, log=LOG, params={"g.k": k})
        np.testing.assert_array_equal(res["nb.neighbors"][r], ref["nb.neighbors"])
