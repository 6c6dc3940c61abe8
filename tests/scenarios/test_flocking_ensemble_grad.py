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
    # any chunking gives the same runs (one run per call, an odd chunk with
    # the last call padded, all at once); the vectorised code of another
    # chunk size may round differently: 1e-12 m
    for chunk, calls in ((1, 8), (3, 3), (8, 1)):
        other = runner.ensemble(seeds=seeds, x0=F.ensemble_x0(seeds, agents=12),
                                chunk=chunk)
        assert other.meta["chunk_size"] == chunk and other.meta["chunks"] == calls
        for port in ("flock.position", "flock.velocity", "view.order"):
            np.testing.assert_allclose(other[port], ens[port], rtol=0, atol=1e-12)


def test_gradient_through_flocking_equals_central_differences_of_numpy_runs():
    """d cost / d (c1, c2, initial velocities) by reverse mode through the
    compiled run equals central finite differences of NumPy runs to 1e-5
    relative; the neighbour sets are frozen (fixed adjacency), as the
    gradient assumes."""
    import jax.numpy as jnp
    n, d = 6, 7.0
    dg, sim = F.make_diagram(agents=n, spread=12.0, t_final=1.0, dt=0.02,
                             neighbors="frozen")
    p0, v0 = F.initial_conditions(n, d, 12.0, 2.0, 1)
    pr = F.pairs(F.frozen_adjacency(p0, 12, 1.2 * d))
    assert len(pr[0]) >= 5
    log = ["flock.position", "law.accel"]

    def cost(res, xp=jnp):
        return F.lattice_cost(res["flock.position"], res["law.accel"], pr, d, xp=xp)

    val, g = av.grad(cost, dg, ["law.c1", "law.c2", "flock.velocity@x0"],
                     sim["t_final"], sim["dt"], log=log, return_value=True)

    def J(params=None, x0=None):
        res = av.simulate(dg, sim["t_final"], sim["dt"], log=log, params=params, x0=x0)
        return cost(res, np)

    assert float(val) == pytest.approx(J(), rel=1e-10)
    h = 1e-4
    for name in ("law.c1", "law.c2"):
        fd = (J(params={name: 1.0 + h}) - J(params={name: 1.0 - h})) / (2 * h)
        assert float(g[name]) == pytest.approx(fd, rel=1e-5)
    gv = np.asarray(g["flock.velocity@x0"])
    fdv = np.zeros_like(gv)
    for a in range(n):
        for b in range(2):
            vp, vm = v0.copy(), v0.copy()
            vp[a, b] += h
            vm[a, b] -= h
            fdv[a, b] = (J(x0={"flock.velocity": vp}) - J(x0={"flock.velocity": vm})) / (2 * h)
    np.testing.assert_allclose(gv, fdv, rtol=0, atol=1e-5 * np.abs(fdv).max())
    assert np.abs(fdv).max() > 1e-3


def test_lattice_cost_by_hand():
    pos = np.array([[[0.0, 0.0], [3.0, 4.0], [10.0, 0.0]]])      # one sample
    acc = np.array([[[1.0, 0.0], [0.0, 2.0], [0.0, 0.0]]])
    # pairs (0,1): |d| = 5, (1,2): sqrt(49+16)
    c = F.lattice_cost(pos, acc, (np.array([0, 1]), np.array([1, 2])), 7.0, effort=0.5)
    want = ((5 - 7.0) ** 2 + (np.sqrt(65.0) - 7.0) ** 2) / 2 + 0.5 * (1 + 4 + 0) / 3
    assert c == pytest.approx(want, rel=1e-14)
