"""Verlet lists (``Neighbors(skin=...)``): the staleness bound against brute
force, the selection against brute force, and compiled runs with a skin equal
to runs without, bit for bit, with rebuilds and overflows."""

import warnings

import numpy as np
import pytest

import avblocks as av
from avblocks.core.errors import SimulationError
from avblocks.environment import Neighbors
from avblocks.utility.spatial import verlet

jax = pytest.importorskip("jax")
jnp = jax.numpy


def _brute(p, r, k, box=None):
    """k nearest others within r: lexsort by (distance^2, index), brute force."""
    d = p[None, :, :2] - p[:, None, :2]
    if box is not None:
        d = d - np.asarray(box) * np.round(d / np.asarray(box))
    d2 = d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1]
    n = len(p)
    dm = np.where((d2 <= r * r) & ~np.eye(n, dtype=bool), d2, np.inf)
    j = np.broadcast_to(np.arange(n), (n, n))
    o = np.lexsort((j, dm), axis=-1)[:, :k]
    fin = np.isfinite(np.take_along_axis(dm, o, 1))
    out = np.where(fin, np.take_along_axis(j, o, 1), -1)
    dist = np.where(fin, np.sqrt(np.take_along_axis(dm, o, 1)), np.inf)
    pad = k - out.shape[1]
    return (np.pad(out, ((0, 0), (0, pad)), constant_values=-1),
            np.pad(dist, ((0, 0), (0, pad)), constant_values=np.inf))


def _lists(p, reach, width=None):
    """Every other point within ``reach`` (brute force), rows in index order."""
    d = p[None, :, :2] - p[:, None, :2]
    ok = (np.hypot(d[..., 0], d[..., 1]) <= reach) & ~np.eye(len(p), dtype=bool)
    width = width or max(1, int(ok.sum(1).max()))
    out = np.full((len(p), width), -1, np.int64)
    for i, row in enumerate(ok):
        js = np.nonzero(row)[0]
        out[i, :len(js)] = js
    return out


def test_staleness_bound_never_misses_a_pair():
    """Whenever ``moved`` says the list is still good, every pair within r
    now was within r + skin at the anchor (checked by brute force), under
    translations, rotations, contractions and random jitter."""
    rng = np.random.default_rng(0)
    r, skin, seen_ok = 1.0, 0.3, 0
    for _ in range(400):
        a = rng.uniform(0, 6, (40, 2))
        ang, scale = rng.normal(0, 0.05), 1 + rng.normal(0, 0.03)
        rot = scale * np.array([[np.cos(ang), -np.sin(ang)], [np.sin(ang), np.cos(ang)]])
        p = (a - 3) @ rot.T + 3 + rng.normal(0, 2, 2) + rng.normal(0, 0.06, a.shape)
        for xp in (np, jnp):
            with jax.enable_x64(True):
                stale = bool(verlet.moved(xp.asarray(p), xp.asarray(a), r, skin, xp))
            if not stale:
                seen_ok += 1
                dn = np.linalg.norm(p[:, None] - p[None], axis=-1)
                da = np.linalg.norm(a[:, None] - a[None], axis=-1)
                assert np.all(da[dn <= r] <= r + skin)
    assert seen_ok > 100                      # the bound is not vacuous
    # a pure translation keeps any list; a move of one point by more than
    # skin/2 does not
    a = rng.uniform(0, 6, (30, 2))
    assert not bool(verlet.moved(a + [50.0, -7.0], a, r, skin))
    b = a.copy()
    b[3] += [0.31, 0.0]
    assert bool(verlet.moved(b, a, r, skin))
    assert bool(verlet.moved(np.full_like(a, np.nan), a, r, skin))


@pytest.mark.parametrize("xp", [np, jnp], ids=["numpy", "jax"])
@pytest.mark.parametrize("case", ["random", "ties", "box", "fov"])
def test_select_equals_brute_force(xp, case):
    with jax.enable_x64(True):
        _select_case(xp, case)


def _select_case(xp, case):
    rng = np.random.default_rng(1)
    p = rng.uniform(0, 8, (90, 2))
    r, k, box, kw = 1.2, 5, None, {}
    if case == "ties":                        # lattice: equal distances, duplicates
        p = np.round(p * 2) / 2
        p[:6] = p[6]
    if case == "box":
        box = (8.0, 8.0)
        p[0], p[1] = [0.05, 0.05], [7.95, 7.95]
    cand = _lists(p, r + 0.4) if box is None else None
    if box is not None:                       # minimum-image lists
        d = p[None] - p[:, None]
        d = d - 8.0 * np.round(d / 8.0)
        ok = (np.hypot(d[..., 0], d[..., 1]) <= r + 0.4) & ~np.eye(len(p), dtype=bool)
        cand = np.full((len(p), ok.sum(1).max()), -1, np.int64)
        for i, row in enumerate(ok):
            cand[i, :row.sum()] = np.nonzero(row)[0]
    # empty slots anywhere in the row, indices increasing
    cand = np.concatenate([np.full((len(p), 3), -1), cand], 1)
    if case == "fov":
        h = rng.uniform(-np.pi, np.pi, len(p))
        kw = dict(heading=xp.asarray(h), fov=2.0)
    idx, dist = verlet.select(xp.asarray(p), xp.asarray(cand), r, k, xp,
                              box=box, **kw)
    if case == "fov":
        from avblocks.environment.neighbors import fov_neighbors
        want, wd = fov_neighbors(np.c_[p, h], r, k, 2.0)
    else:
        want, wd = _brute(p, r, k, box)
    np.testing.assert_array_equal(np.asarray(idx), want)
    np.testing.assert_allclose(np.asarray(dist), wd, rtol=1e-12)


def _converging(n=60, skin=0.0, **kw):
    """Agents pulled to the origin: dp/dt = -2 p (lists go stale fast)."""
    rng = np.random.default_rng(0)
    d = av.Diagram()
    ag = d.add(av.vehicles.SingleIntegrator(rng.uniform(-10, 10, (n, 2))), name="ag")
    g = d.add(av.blocks.Gain(-2.0), name="g")
    nb = d.add(Neighbors(n, 4, radius=1.0, input="position", skin=skin, **kw), name="nb")
    d.connect(ag.position, g.u)
    d.connect(g.y, ag.velocity)
    d.connect(ag.position, nb.position)
    return d


def _swirl(n=70, skin=0.0, **kw):
    """Agents circling the origin and drifting: rotation plus translation."""
    rng = np.random.default_rng(2)
    d = av.Diagram()
    ag = d.add(av.vehicles.SingleIntegrator(rng.uniform(-6, 6, (n, 2))), name="ag")
    turn = d.add(av.blocks.Function(
        lambda t, position, xp: xp.stack([-position[:, 1] + 1.5,
                                          position[:, 0] + 0.3 * xp.sin(3 * position[:, 0])],
                                         axis=1),
        inputs={"position": (n, 2)}, outputs={"y": (n, 2)}), name="turn")
    nb = d.add(Neighbors(n, 6, radius=1.5, input="position", skin=skin, **kw), name="nb")
    d.connect(ag.position, turn.position)
    d.connect(turn.y, ag.velocity)
    d.connect(ag.position, nb.position)
    return d


@pytest.mark.parametrize("make,method", [(_converging, "cells"), (_swirl, "cells"),
                                         (_swirl, "dense")])
def test_skin_run_equals_fresh_search_bit_for_bit(make, method):
    log = ["nb.neighbors", "nb.distance"]
    ref = av.simulate(make(), 1.5, dt=0.05, log=log)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)      # re-planning is fine here
        fresh = av.simulate(make(method=method), 1.5, dt=0.05, log=log, backend="jax")
        res = av.simulate(make(skin=0.3, method=method), 1.5, dt=0.05, log=log,
                          backend="jax")
    np.testing.assert_array_equal(res["nb.neighbors"], ref["nb.neighbors"])
    np.testing.assert_array_equal(res["nb.neighbors"], fresh["nb.neighbors"])
    np.testing.assert_array_equal(res["nb.distance"], fresh["nb.distance"])
    # the list was rebuilt during the run (its anchor is not the start)
    anchor = np.asarray(res.final_state["nb.verlet_anchor"])
    start = make().build().blocks[0].initial_state()["position"]
    assert np.abs(anchor - start).max() > 1.0
    assert int(res.final_state["nb.verlet_built"]) == 1


def test_skin_with_box_and_fov_equals_numpy():
    rng = np.random.default_rng(4)
    n = 50
    d = av.Diagram()
    ag = d.add(av.vehicles.Unicycle(np.c_[rng.uniform(0, 10, (n, 2)),
                                          rng.uniform(-np.pi, np.pi, n)]), name="ag")
    u = d.add(av.blocks.Constant(np.c_[np.full(n, 2.0), rng.uniform(-1, 1, n)]), name="u")
    nb = d.add(Neighbors(n, 5, radius=1.5, fov=4.0, input="pose", skin=0.4), name="nb")
    d.connect(u.y, ag.cmd)
    d.connect(ag.pose, nb.pose)
    log = ["nb.neighbors"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        a = av.simulate(d, 1.0, dt=0.05, log=log)
        b = av.simulate(d, 1.0, dt=0.05, log=log, backend="jax")
    np.testing.assert_array_equal(a["nb.neighbors"], b["nb.neighbors"])

    box = (10.0, 10.0)
    p = rng.uniform(0, 10, (n, 2))
    p[0], p[1] = [0.05, 0.05], [9.95, 9.95]
    d = av.Diagram()
    c = d.add(av.blocks.Constant(p), name="c")
    nb = d.add(Neighbors(n, 5, radius=1.0, input="position", box=box, skin=0.5), name="nb")
    d.connect(c.y, nb.position)
    a = av.simulate(d, 0.1, dt=0.05, log=log)
    b = av.simulate(d, 0.1, dt=0.05, log=log, backend="jax")
    np.testing.assert_array_equal(a["nb.neighbors"], b["nb.neighbors"])
    np.testing.assert_array_equal(a["nb.neighbors"][-1], _brute(p, 1.0, 5, box)[0])


def test_skin_overflow_replans_or_raises():
    log = ["nb.neighbors"]
    ref = av.simulate(_converging(), 3.0, dt=0.05, log=log)
    run = av.compile(_converging(skin=0.3), 3.0, dt=0.05, log=log)
    width = run.compiled.blocks[run.compiled.index("nb")].initial_state()["verlet_list"]
    with pytest.warns(RuntimeWarning, match="nb"):
        res = run()
    grown = run.compiled.blocks[run.compiled.index("nb")].initial_state()["verlet_list"]
    assert grown.shape[1] > width.shape[1]           # the list state took the new width
    np.testing.assert_array_equal(res["nb.neighbors"], ref["nb.neighbors"])
    run = av.compile(_converging(skin=0.3, capacity=6), 3.0, dt=0.05, log=log,
                     on_overflow="raise")
    with pytest.raises(SimulationError, match="nb.*(capacity|hits)"):
        run()


def test_skin_validation_and_defaults():
    with pytest.raises(av.ParameterError, match="skin"):
        Neighbors(5, 2, radius=1.0, skin=-1.0)
    assert Neighbors(5, 2).skin == 0.0                       # unlimited radius: no skin
    assert Neighbors(5, 2, radius=1.0, skin=0.5).skin == 0.5
    assert Neighbors(5, 2, radius=1.0, skin=9.0, box=(4.0, 4.0)).skin == 1.0
    assert "verlet_list" not in Neighbors(5, 2, radius=1.0).initial_state()


def test_gradient_with_a_skin_equals_the_fresh_search_gradient():
    """The list is integers built from stop_gradient positions, so a gradient
    through a run with a skin (rebuilds in a while_loop) is the fresh one."""
    def cost(res):
        dd = res["nb.distance"]
        return (dd * (dd > 0)).sum()

    def make(skin):
        d = _converging(40, skin=skin)
        return av.compile(d, 0.6, dt=0.05, log=["nb.distance"])

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        g0 = make(0.0).grad(cost, ["g.k"])["g.k"]
        g1 = make(0.3).grad(cost, ["g.k"])["g.k"]
    assert np.isfinite(g0) and g0 != 0
    np.testing.assert_allclose(g1, g0, rtol=1e-12)
