"""utility.spatial: the cell-list search against brute force (and the k-d tree)."""

import numpy as np
import pytest

from avblocks.utility import spatial as sp


def brute(p, r, k, box=None, fov=None, heading=None):
    """Independent truth: all pairs, lexsort by (distance, index)."""
    d = p[None, :, :] - p[:, None, :]
    if box is not None:
        d = d - np.asarray(box) * np.round(d / np.asarray(box))
    dist = np.sqrt((d ** 2).sum(-1))
    n = len(p)
    ok = (dist <= r) & ~np.eye(n, dtype=bool)
    if fov is not None:
        rel = np.arctan2(d[..., 1], d[..., 0]) - heading[:, None]
        rel = np.abs((rel + np.pi) % (2 * np.pi) - np.pi)
        ok &= rel <= fov / 2 + 1e-12
    dm = np.where(ok, dist, np.inf)
    j = np.broadcast_to(np.arange(n), (n, n))
    o = np.lexsort((j, dm), axis=-1)[:, :k]
    i = np.take_along_axis(np.where(ok, j, -1), o, 1)
    dd = np.take_along_axis(dm, o, 1)
    if i.shape[1] < k:
        i = np.pad(i, ((0, 0), (0, k - i.shape[1])), constant_values=-1)
        dd = np.pad(dd, ((0, 0), (0, k - dd.shape[1])), constant_values=np.inf)
    return i, dd


def cases(seed, count):
    rng = np.random.default_rng(seed)
    for trial in range(count):
        n = int(rng.integers(1, 250))
        side = rng.uniform(1, 20)
        p = rng.uniform(0, side, (n, 2))
        if trial % 3 == 0:
            p = np.round(p * 2) / 2          # duplicates, exact ties, cell borders
        r = float(rng.uniform(0.3, 3))
        k = int(rng.integers(1, 15))
        box = None
        if trial % 4 == 1:
            box = (side * 1.01, side * 1.01)
            r = min(r, side * 0.5)
        yield rng, p, r, k, box


def test_nearest_numpy_matches_brute_force():
    for rng, p, r, k, box in cases(1, 30):
        cells = sp.CellList(r, box=box)
        i, d, _ = sp.nearest(cells, p, r, k)
        bi, bd = brute(p, r, k, box)
        np.testing.assert_array_equal(i, bi)
        np.testing.assert_allclose(d, bd, rtol=1e-12)
        h = rng.uniform(-np.pi, np.pi, len(p))
        fov = float(rng.uniform(0.5, 6))
        i, d, _ = sp.nearest(cells, p, r, k, heading=h, fov=fov)
        np.testing.assert_array_equal(i, brute(p, r, k, box, fov, h)[0])
        plan = sp.plan_cells(p, r, box=box)
        i, d, need = sp.nearest(plan, p, r, k)
        np.testing.assert_array_equal(i, bi)
        assert plan.exceeded(need) is None


@pytest.mark.parametrize("threads", [False, True], ids=["one thread", "every core"])
def test_kd_nearest_equals_brute_force_with_ties(threads, monkeypatch):
    """Also with the tree queried on every core (as from
    ``kdtree.PARALLEL_QUERY`` points on): the same answers."""
    from avblocks.utility.spatial import kdtree
    if threads:
        monkeypatch.setattr(kdtree, "PARALLEL_QUERY", 1)
    for _, p, r, k, box in cases(5, 40):
        i, d = sp.kd_nearest(p, r, k, box=box)
        bi, bd = brute(p, r, k, box)
        np.testing.assert_array_equal(i, bi)
        np.testing.assert_allclose(d, bd, rtol=1e-12)


def test_exactly_at_radius_is_inside_and_n1():
    p = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 2.0], [3.0, 0.0]])
    cells = sp.CellList(1.0)
    i, d, _ = sp.nearest(cells, p, 1.0, 3)
    assert i.tolist() == [[1, -1, -1], [0, -1, -1], [-1, -1, -1], [-1, -1, -1]]
    i, d, _ = sp.nearest(cells, p[:1], 1.0, 2)
    assert i.tolist() == [[-1, -1]] and np.isinf(d).all()


def test_chunked_rows_equal_unchunked(monkeypatch):
    rng = np.random.default_rng(3)
    p = rng.uniform(0, 5, (120, 2))
    import importlib
    monkeypatch.setattr(importlib.import_module("avblocks.utility.spatial.queries"),
                        "CHUNK", 7)        # the module the queries read it from
    i, _, _ = sp.nearest(sp.CellList(1.0), p, 1.0, 5)
    np.testing.assert_array_equal(i, brute(p, 1.0, 5)[0])


def test_within_is_the_radius_set():
    rng = np.random.default_rng(4)
    p = np.round(rng.uniform(0, 6, (150, 2)) * 2) / 2
    idx, dist, need = sp.within(sp.CellList(1.0), p, 1.0)
    full = np.linalg.norm(p[:, None] - p[None], axis=-1)
    for a in range(len(p)):
        want = set(np.nonzero((full[a] <= 1.0) & (np.arange(len(p)) != a))[0])
        got = set(idx[a][idx[a] >= 0].tolist())
        assert got == want
    assert int(need.hits) == max(len(s) for s in [set()] + [
        set(np.nonzero((full[a] <= 1.0) & (np.arange(len(p)) != a))[0]) for a in range(len(p))])


@pytest.mark.parametrize("seed", range(6))
def test_plan_counts_the_candidates_and_hits_of_the_most_crowded_point(seed):
    """plan_cells' capacity and hits are headroom times the most candidates
    and the most others within reach of one point: counted here by all
    pairs (hits, periodic minimum image) and by the cells around each point
    (candidates), on clouds with lattice ties at exactly the reach,
    duplicates and a periodic box."""
    rng = np.random.default_rng(seed)
    n, r = 300, 1.0
    box = None if seed % 2 == 0 else np.array([12.0, 9.0])
    p = rng.uniform(0, 9, (n, 2))
    if seed % 3 == 1:
        p = np.round(p * 2) / 2                  # pairs at exactly r = 1.0
    if seed % 3 == 2:
        p[: n // 4] = p[0]                       # a stack of duplicates
    d = p[None, :, :] - p[:, None, :]
    if box is not None:
        d = d - box * np.round(d / box)
    within_r = (np.sqrt((d ** 2).sum(-1)) <= r) & ~np.eye(n, dtype=bool)
    most_hits = int(within_r.sum(1).max())
    plan = sp.plan_cells(p, r, box=box, headroom=1.0, min_capacity=1)
    assert plan.hits == max(1, most_hits)
    # candidates: the cell list's own rows (the need of a within search,
    # which is how plans were counted before the tree counted the hits)
    _, _, need = sp.within(sp.CellList(r, box=box), p, r)
    assert plan.capacity == int(need.capacity)
    assert plan.hits == max(1, int(need.hits))
    assert int(need.capacity) >= most_hits
    wide = sp.plan_cells(p, r, box=box, headroom=1.5)
    assert wide.hits == max(8, int(np.ceil(1.5 * most_hits)))


def test_overflow_is_reported():
    p = np.random.default_rng(0).uniform(0, 10, (200, 2))
    plan = sp.plan_cells(p, 1.0)
    crowd = np.zeros_like(p) + np.random.default_rng(1).uniform(0, 0.1, p.shape)
    _, _, need = sp.nearest(plan, crowd, 1.0, 4)
    msg = plan.exceeded(need)
    assert msg and "capacity" in msg
    grown = plan.grown(need)
    assert grown.capacity >= int(need.capacity)


def test_jit_matches_brute_force():
    jax = pytest.importorskip("jax")
    import jax.numpy as jnp
    with jax.enable_x64(True):
        for rng, p, r, k, box in cases(2, 8):
            plan = sp.plan_cells(p, r, box=box)
            h = rng.uniform(-np.pi, np.pi, len(p))
            fov = float(rng.uniform(0.5, 6))
            f = jax.jit(lambda q, h, plan=plan, r=r, k=k, fov=fov:
                        sp.nearest(plan, q, r, k, xp=jnp, heading=h, fov=fov)[:2])
            i, d = f(jnp.asarray(p), jnp.asarray(h))
            bi, bd = brute(p, r, k, box, fov, h)
            np.testing.assert_array_equal(np.asarray(i), bi)
            np.testing.assert_allclose(np.asarray(d), bd, rtol=1e-12)


def test_jit_chunked_lax_map(monkeypatch):
    import importlib

    jax = pytest.importorskip("jax")
    import jax.numpy as jnp
    monkeypatch.setattr(importlib.import_module("avblocks.utility.spatial.queries"),
                        "TRACED_CHUNK", 16)    # 100 rows: 7 chunks through lax.map
    p = np.random.default_rng(7).uniform(0, 6, (100, 2))
    with jax.enable_x64(True):
        plan = sp.plan_cells(p, 1.0)
        i = jax.jit(lambda q: sp.nearest(plan, q, 1.0, 6, xp=jnp)[0])(jnp.asarray(p))
    np.testing.assert_array_equal(np.asarray(i), brute(p, 1.0, 6)[0])


def test_grad_of_neighbour_distances():
    jax = pytest.importorskip("jax")
    import jax.numpy as jnp
    p = np.random.default_rng(8).uniform(0, 4, (40, 2))
    with jax.enable_x64(True):
        plan = sp.plan_cells(p, 1.0)

        def cost(q):
            i, d, _ = sp.nearest(plan, q, 1.0, 4, xp=jnp)
            return jnp.sum(jnp.where(i >= 0, d, 0.0) ** 3)

        g = np.asarray(jax.grad(cost)(jnp.asarray(p)))
    # central differences with the neighbour sets fixed (none cross r here)
    h = 1e-6
    for a in [(0, 0), (5, 1), (17, 0)]:
        e = np.zeros_like(p)
        e[a] = h

        def c_np(q):
            i, d, _ = sp.nearest(sp.CellList(1.0), q, 1.0, 4)
            return np.sum(np.where(i >= 0, d, 0.0) ** 3)
        fd = (c_np(p + e) - c_np(p - e)) / (2 * h)
        assert g[a] == pytest.approx(fd, rel=1e-5, abs=1e-8)


def test_far_apart_points_report_their_span():
    # a frame of ~4e19 cells: more than int64 keys address; the need says so
    p = np.array([[0.0, 0.0], [0.5, 0.0], [3e9, 3e9], [3e9 + 0.5, 3e9]])
    _, _, need = sp.nearest(sp.CellList(1.0), p, 1.0, 2)
    assert float(need.span) > 1
    assert "span" in sp.CellList(1.0, 4).exceeded(need)
    _, _, need = sp.nearest(sp.CellList(1.0), p[:2], 1.0, 2)
    assert float(need.span) < 1e-10


@pytest.mark.parametrize("bits", [64, 32])
def test_jit_packed_sort_equals_stable_argsort(bits):
    """Both branches (packed keys, and the argsort where ``cells * N`` is
    too large to pack), with 64-bit keys and with the 32-bit keys of a
    float32 program (packed up to ``2^30``)."""
    jax = pytest.importorskip("jax")
    import jax.numpy as jnp
    rng = np.random.default_rng(0)
    keys = rng.integers(0, 50, 300)
    big = 1e18 if bits == 64 else 2.0 ** 30 / 300 * 1.01
    cells = int(2.0 ** 30 / 300 * 0.99)           # packed, keys up to near the limit
    far = np.concatenate([rng.integers(cells - 40, cells, 150), rng.integers(0, 40, 150)])
    it = np.int64 if bits == 64 else np.int32
    with jax.enable_x64(bits == 64):
        k = jnp.asarray(keys.astype(it))
        fast = jax.jit(lambda k: sp._sort(k, jnp, 50.0))(k)
        slow = jax.jit(lambda k: sp._sort(k, jnp, big))(k)
        edge = jax.jit(lambda k: sp._sort(k, jnp, float(cells)))(jnp.asarray(far.astype(it)))
    want = np.argsort(keys, kind="stable")
    np.testing.assert_array_equal(np.asarray(fast), want)
    np.testing.assert_array_equal(np.asarray(slow), want)
    np.testing.assert_array_equal(np.asarray(edge), np.argsort(far, kind="stable"))


@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_k_smallest_integer_minima_of_nonnegative_floats_are_exact(dtype):
    """``nonneg=True`` (traced: minima of the float bits as integers) selects
    what the float minima select, with ties, zeros and infinities, along
    either axis; against NumPy's float passes and a sort. (Subnormal
    squared distances, below 1e-308, are not compared: XLA on a CPU reads
    them as zero in float comparisons, with or without ``nonneg``.)"""
    jax = pytest.importorskip("jax")
    from avblocks.core.compiled import _jax
    from avblocks.utility.spatial.queries import k_smallest
    rng = np.random.default_rng(11)
    d2 = np.round(rng.uniform(0, 6, (40, 30))).astype(dtype)     # many ties
    d2[rng.uniform(size=d2.shape) < 0.3] = np.inf
    d2[0, :5] = 0.0
    idx = np.broadcast_to(np.arange(30, dtype=np.int32), d2.shape)
    with _jax.x64(dtype == "float64"):
        for axis in (1, 0):
            a = d2 if axis == 1 else d2.T.copy()
            i = idx if axis == 1 else idx.T.copy()
            want = k_smallest(a, i, 7, np, axis=axis)
            got = jax.jit(lambda a, i, ax=axis: k_smallest(a, i, 7, jax.numpy, axis=ax,
                                                           nonneg=True))(a, i)
            np.testing.assert_array_equal(np.asarray(got[0]), want[0])
            np.testing.assert_array_equal(np.asarray(got[1]), want[1])
    # independent truth: a lexsort of (d2, index) per row
    order = np.lexsort((idx, d2), axis=1)[:, :7]
    np.testing.assert_array_equal(np.take_along_axis(idx, order, 1),
                                  k_smallest(d2, idx, 7, np)[1])


def test_k_smallest_integer_minima_keep_the_gradient():
    """The distances ``nonneg=True`` selects carry the gradient ``min`` has
    (the dense neighbour search's ``distance`` output is differentiable)."""
    jax = pytest.importorskip("jax")
    from avblocks.core.compiled import _jax
    from avblocks.environment.neighbors import dense_nearest
    from avblocks.utility.spatial.queries import k_smallest
    rng = np.random.default_rng(3)
    p = rng.uniform(0, 10, (20, 2))
    d2 = rng.uniform(0, 5, (12, 9))
    idx = np.broadcast_to(np.arange(9, dtype=np.int32), d2.shape)
    with _jax.x64(True):
        for nonneg in (False, True):
            g = jax.grad(lambda a, nn=nonneg: jax.numpy.sum(
                k_smallest(a, idx, 4, jax.numpy, nonneg=nn)[0] ** 2))(d2)
            want = np.zeros_like(d2)             # d/da of the 4 smallest a^2: 2 a there
            rows = np.arange(12)[:, None]
            cols = np.argsort(d2, axis=1)[:, :4]
            want[rows, cols] = 2 * d2[rows, cols]
            np.testing.assert_allclose(np.asarray(g), want, rtol=1e-12, atol=0)

        def cost(q):
            i, d = dense_nearest(q, 4.0, 5, jax.numpy)
            return jax.numpy.sum(jax.numpy.where(i >= 0, d, 0.0))
        g = np.asarray(jax.grad(cost)(p))
        e = np.zeros_like(p)
        e[3, 0] = 1e-6
        fd = (float(cost(p + e)) - float(cost(p - e))) / 2e-6
        assert np.abs(g).max() > 0.1 and abs(g[3, 0] - fd) < 1e-6


@pytest.mark.parametrize("seed", range(8))
def test_the_plans_candidate_count_by_cell_counts_equals_counting_each_point(seed):
    """plan_cells counts a free-space cloud's most candidates from a count
    per cell summed over each cell's window (queries._most_candidates);
    counted here point by point: the points whose integer cell lies within
    ``split`` cells of the point's own on every axis (2-D and 3-D clouds,
    clusters, duplicates, integer coordinates on cell edges)."""
    from avblocks.utility.spatial import queries
    rng = np.random.default_rng(seed)
    dim = 2 if seed % 2 == 0 else 3
    n = int(rng.integers(2, 300))
    p = rng.uniform(-15, 15, (n, dim)) * (0.05 if seed % 4 == 1 else 1.0)
    if seed % 3 == 0:
        p[: n // 3] = p[-1]
    if seed % 4 == 2:
        p = np.round(p)
    cells = sp.CellList(float(rng.uniform(0.5, 4.0)), dim=dim)
    c = np.floor(p / np.asarray(cells.cell_edges())).astype(int)
    near = np.all(np.abs(c[:, None, :] - c[None, :, :]) <= cells.split, axis=-1)
    most = int(near.sum(axis=1).max())
    got = queries._most_candidates(cells, p)
    assert got == most
    assert sp.plan_cells(p, cells.reach, headroom=1.0, min_capacity=1,
                         count_hits=False) == sp.CellList(cells.reach, most, dim=dim)
