"""Neighbors in the compiled engine: equal to the NumPy engine; static plans,
overflow re-planning and raising."""

import warnings

import numpy as np
import pytest

import avblocks as av
from avblocks.core.errors import SimulationError
from avblocks.environment import Neighbors

pytest.importorskip("jax")


def _diagram(p, **kw):
    d = av.Diagram()
    c = d.add(av.blocks.Constant(p), name="c")
    nb = d.add(Neighbors(len(p), kw.pop("k", 5), **kw), name="nb")
    d.connect(c.y, nb.pose if kw.get("input", "pose") == "pose" else nb.position)
    return d


def _both(d):
    log = ["nb.neighbors", "nb.distance"]
    r1 = av.simulate(d, 0.04, dt=0.02, log=log)
    r2 = av.simulate(d, 0.04, dt=0.02, log=log, backend="jax")
    return r1, r2


def _brute(p, r, k, box=None):
    d = p[None, :, :2] - p[:, None, :2]
    if box is not None:
        d = d - np.asarray(box) * np.round(d / np.asarray(box))
    dist = np.hypot(d[..., 0], d[..., 1])
    n = len(p)
    ok = (dist <= r) & ~np.eye(n, dtype=bool)
    dm = np.where(ok, dist, np.inf)
    j = np.broadcast_to(np.arange(n), (n, n))
    o = np.lexsort((j, dm), axis=-1)[:, :k]
    out = np.where(np.isfinite(np.take_along_axis(dm, o, 1)), np.take_along_axis(j, o, 1), -1)
    return np.pad(out, ((0, 0), (0, k - out.shape[1])), constant_values=-1)


@pytest.mark.parametrize("case", ["radius", "grid", "knn", "fov", "box", "one"])
def test_compiled_equals_numpy_and_brute_force(case):
    rng = np.random.default_rng(3)
    n, kw, box = 80, dict(radius=1.5, input="position"), None
    p = rng.uniform(0, 8, (n, 2))
    if case == "grid":                      # duplicates, ties, points on cell borders
        p = np.round(p * 2) / 2
        p[:5] = p[5]
    elif case == "knn":
        kw = dict(input="position")
    elif case == "fov":
        p = np.c_[p, rng.uniform(-np.pi, np.pi, n)]
        kw = dict(radius=2.0, fov=2.0, input="pose")
    elif case == "box":
        p = rng.uniform(0, 8, (n, 2))
        p[0] = [0.05, 0.05]
        p[1] = [7.95, 7.95]                 # 0.1 sqrt(2) apart across the corner
        box = (8.0, 8.0)
        kw = dict(radius=1.0, input="position", box=box)
    elif case == "one":
        p = p[:1]
    r1, r2 = _both(_diagram(p, **kw))
    np.testing.assert_array_equal(r1["nb.neighbors"], r2["nb.neighbors"])
    np.testing.assert_allclose(r1["nb.distance"], r2["nb.distance"], rtol=1e-12,
                               atol=1e-12)
    if case in ("radius", "grid", "box", "one", "knn"):
        want = _brute(p, kw.get("radius", np.inf), 5, box)
        np.testing.assert_array_equal(r1["nb.neighbors"][-1], want)
    if case == "box":
        assert r1["nb.neighbors"][-1][0, 0] == 1


def _converging(n=60, **kw):
    """Agents pulled to the origin: dp/dt = -2 p (all end in one cell)."""
    rng = np.random.default_rng(0)
    d = av.Diagram()
    ag = d.add(av.vehicles.SingleIntegrator(rng.uniform(-10, 10, (n, 2))), name="ag")
    g = d.add(av.blocks.Gain(-2.0), name="g")
    nb = d.add(Neighbors(n, 4, radius=1.0, input="position", **kw), name="nb")
    d.connect(ag.position, g.u)
    d.connect(g.y, ag.velocity)
    d.connect(ag.position, nb.position)
    return d


def test_overflow_replans_recompiles_and_matches_numpy():
    d = _converging()
    log = ["nb.neighbors", "nb.distance"]
    ref = av.simulate(d, 3.0, dt=0.05, log=log)
    run = av.compile(d, 3.0, dt=0.05, log=log)
    planned = run.compiled.blocks[run.compiled.index("nb")].search.cells.capacity
    with pytest.warns(RuntimeWarning, match="nb.*capacity"):
        res = run()
    grown = run.compiled.blocks[run.compiled.index("nb")].search.cells.capacity
    assert grown > planned
    np.testing.assert_array_equal(res["nb.neighbors"], ref["nb.neighbors"])
    with warnings.catch_warnings():
        warnings.simplefilter("error")      # the grown plan suffices now
        res2 = run()
    np.testing.assert_array_equal(res2["nb.neighbors"], ref["nb.neighbors"])


def test_overflow_raises_when_asked():
    run = av.compile(_converging(), 3.0, dt=0.05, log=["nb.neighbors"],
                     on_overflow="raise")
    with pytest.raises(SimulationError, match=r"nb.*capacity: a point had \d+ candidates"
                                              r".*capacity is \d+"):
        run()


def test_fixed_capacity_is_kept_and_overflow_raises_in_ensemble():
    run = av.compile(_converging(capacity=6), 3.0, dt=0.05, log=["nb.neighbors"],
                     on_overflow="raise")
    assert run.compiled.blocks[run.compiled.index("nb")].search.cells.capacity == 6
    with pytest.raises(SimulationError, match="capacity"):
        run.ensemble(x0={"ag.position": np.stack(
            [np.random.default_rng(s).uniform(-10, 10, (60, 2)) for s in range(3)])})


def test_ensemble_overflow_replans():
    d = _converging()
    x0 = np.stack([np.random.default_rng(s).uniform(-10, 10, (60, 2)) for s in range(3)])
    run = av.compile(d, 3.0, dt=0.05, log=["nb.neighbors"])
    with pytest.warns(RuntimeWarning, match="re-planned"):
        res = run.ensemble(x0={"ag.position": x0})
    for r in range(3):
        ref = av.simulate(d, 3.0, dt=0.05, log=["nb.neighbors"],
                          x0={"ag.position": x0[r]})
        np.testing.assert_array_equal(res["nb.neighbors"][r], ref["nb.neighbors"])


def test_gradient_run_checks_overflow_too():
    run = av.compile(_converging(), 3.0, dt=0.05, log=["ag.position"], on_overflow="raise")

    def cost(res):
        return (res["ag.position"][-1] ** 2).sum()

    with pytest.raises(SimulationError, match="capacity"):
        run.grad(cost, ["g.k"])


def test_float32_compiled_run_equals_numpy():
    p = np.random.default_rng(0).uniform(0, 10, (60, 2))
    d = _diagram(p, radius=2.0, input="position")
    a = av.simulate(d, 0.1, dt=0.05, log=["nb.neighbors"])
    b = av.simulate(d, 0.1, dt=0.05, log=["nb.neighbors"], backend="jax", dtype="float32")
    np.testing.assert_array_equal(a["nb.neighbors"], b["nb.neighbors"])
