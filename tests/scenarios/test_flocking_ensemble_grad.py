"""Ensembles and gradients through the interacting flocking scenario."""

import numpy as np
import pytest

import avblocks as av
from avblocks.scenarios import flocking as F

jax = pytest.importorskip("jax")


def _settings(sim):
    return {k: v for k, v in sim.items() if k != "seed"}


def test_ensemble_member_k_equals_the_single_run_with_seed_k():
    seeds = list(range(8))
    kw = dict(agents=12, t_final=1.0, dt=0.02, log_every=5)
    dg, sim = F.make_diagram(seed=seeds[0], **kw)
    runner = av.compile(dg, **_settings(sim))
    ens = runner.ensemble(seeds=seeds, x0=F.ensemble_x0(seeds, agents=12))
    assert ens["flock.position"].shape == (8, 11, 12, 2)
    for k in (0, 3, 7):
        dk, sk = F.make_diagram(seed=k, **kw)
        one = av.simulate(dk, backend="jax", **sk)
        np.testing.assert_allclose(ens["flock.position"][k], one["flock.position"],
                                   rtol=0, atol=1e-10)
        np.testing.assert_allclose(ens["flock.velocity"][k], one["flock.velocity"],
                                   rtol=0, atol=1e-10)
    # independent truth for one member: the NumPy engine
    d5, s5 = F.make_diagram(seed=5, **kw)
    ref = av.simulate(d5, **s5)
    np.testing.assert_allclose(ens["flock.position"][5], ref["flock.position"],
                               rtol=0, atol=1e-9)
    # the members differ (they start differently)
    assert np.abs(ens["flock.position"][1, 0] - ens["flock.position"][2, 0]).max() > 1.0
