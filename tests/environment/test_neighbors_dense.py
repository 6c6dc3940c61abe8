"""Neighbors(method="dense"|"auto"): every pair compared in compiled runs;
the same neighbours, in the same order, as the k-d tree (independent truth:
SciPy's cKDTree through kd_nearest, and a brute-force lexsort)."""

import numpy as np
import pytest

import avblocks as av
from avblocks.environment import Neighbors
from avblocks.environment.neighbors import DENSE_MAX, dense_nearest
from avblocks.utility import spatial as sp


def brute(p, r, k):
    n = len(p)
    d = np.sqrt(((p[:, None] - p[None]) ** 2).sum(-1))
    idx = -np.ones((n, k), int)
    for i in range(n):
        ok = [j for j in range(n) if j != i and d[i, j] <= r]
        ok = sorted(ok, key=lambda j: (d[i, j], j))[:k]
        idx[i, :len(ok)] = ok
    return idx


@pytest.mark.parametrize("seed", range(6))
def test_dense_nearest_equals_kd_tree_and_brute_force(seed):
    rng = np.random.default_rng(seed)
    p = rng.uniform(0, 20, (60, 2))
    if seed % 2:
        p = np.round(p)                 # lattice points: many tied distances
    i1, d1 = dense_nearest(p, 5.0, 12, np)
    i2, d2 = sp.kd_nearest(p, 5.0, 12)
    np.testing.assert_array_equal(i1, i2)
    np.testing.assert_array_equal(np.where(i1 >= 0, d1, 0), np.where(i2 >= 0, d2, 0))
    if not seed % 2:                    # brute force in sqrt distances (no ties)
        np.testing.assert_array_equal(i1, brute(p, 5.0, 12))


def test_compiled_dense_and_auto_equal_numpy_and_plan_no_search():
    pytest.importorskip("jax")
    rng = np.random.default_rng(3)
    n = 40
    p0 = rng.uniform(0, 15, (n, 2))
    for method in ("dense", "auto"):
        d = av.Diagram()
        fl = d.add(av.vehicles.SingleIntegrator(p0), name="fl")
        c = d.add(av.blocks.Constant(rng.uniform(-1, 1, (n, 2))), name="c")
        blk = Neighbors(n, 6, radius=3.0, input="position", method=method)
        nb = d.add(blk, name="nb")
        d.connect(c.y, fl.velocity)
        d.connect(fl.position, nb.position)
        assert blk.searches() == [blk.search]  # planned: the selection passes
        a = av.simulate(d, 2.0, dt=0.1, log=[nb.neighbors, nb.distance])
        b = av.simulate(d, 2.0, dt=0.1, log=[nb.neighbors, nb.distance], backend="jax")
        np.testing.assert_array_equal(a[nb.neighbors], b[nb.neighbors])
        np.testing.assert_allclose(a[nb.distance], b[nb.distance], rtol=0, atol=1e-12)
    assert Neighbors(DENSE_MAX + 1, 4, radius=1.0, method="auto").searches() != []
    assert Neighbors(n, 4, radius=1.0).searches() != []      # default: the cell list
    with pytest.raises(av.ParameterError, match="method"):
        Neighbors(n, 4, radius=1.0, method="kd")


def test_traced_dense_nearest_equals_numpy_on_ties():
    jax = pytest.importorskip("jax")
    import jax.numpy as jnp
    rng = np.random.default_rng(7)
    p = np.round(rng.uniform(0, 10, (50, 2)))          # many tied distances
    from avblocks.core.compiled import _jax
    with _jax.x64(True):
        for k in (3, 12, 60):                          # k > n pads
            i1, d1 = dense_nearest(p, 3.0, k, np)
            i2, d2 = jax.jit(lambda q: dense_nearest(q, 3.0, k, jnp))(p)  # noqa: B023
            np.testing.assert_array_equal(i1, np.asarray(i2))
            np.testing.assert_array_equal(d1, np.asarray(d2))


def _gathering(n=30, k=12, method="dense"):
    """Agents pulled to the origin (dp/dt = -2 p): about one other within
    the radius of each at the start (the plan: hits = 8 < k passes), all of
    them at the end."""
    rng = np.random.default_rng(5)
    d = av.Diagram()
    ag = d.add(av.vehicles.SingleIntegrator(rng.uniform(-15, 15, (n, 2))), name="ag")
    g = d.add(av.blocks.Gain(-2.0), name="g")
    nb = d.add(Neighbors(n, k, radius=3.0, input="position", method=method), name="nb")
    d.connect(ag.position, g.u)
    d.connect(g.y, ag.velocity)
    d.connect(ag.position, nb.position)
    return d


def test_dense_passes_follow_the_plan_and_an_overflow_is_caught():
    pytest.importorskip("jax")
    import warnings
    log = ["nb.neighbors", "nb.distance"]
    d = _gathering()
    ref = av.simulate(d, 2.0, dt=0.05, log=log)
    assert (ref["nb.neighbors"][-1] >= 0).sum(axis=1).min() == 12   # all k used at the end
    # the passes cut to the plan: an agent with more candidates is no silent error
    strict = av.compile(d, 2.0, dt=0.05, log=log, on_overflow="raise")
    plan = strict.compiled.blocks[strict.compiled.index("nb")].search.cells
    assert plan.hits == 8
    with pytest.raises(av.SimulationError, match=r"nb.*hits: a point had 29 others"):
        strict()
    # replan (the default): warned, compiled again with room, equal to NumPy
    run = av.compile(_gathering(), 2.0, dt=0.05, log=log)
    with pytest.warns(RuntimeWarning, match="nb.*hits"):
        res = run()
    assert run.compiled.blocks[run.compiled.index("nb")].search.cells.hits >= 29
    np.testing.assert_array_equal(res["nb.neighbors"], ref["nb.neighbors"])
    np.testing.assert_allclose(res["nb.distance"], ref["nb.distance"], rtol=0, atol=1e-12)
    # a short run within the plan: the cut passes give the full selection
    short = av.compile(_gathering(), 0.1, dt=0.05, log=log)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        got = short()
    want = av.simulate(_gathering(), 0.1, dt=0.05, log=log)
    np.testing.assert_array_equal(got["nb.neighbors"], want["nb.neighbors"])
