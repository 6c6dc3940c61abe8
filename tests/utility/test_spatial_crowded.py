"""The traced k-nearest search on crowded clouds: each chunk of rows (each
step, when the rows fit one chunk) takes the smallest width class that
holds its most crowded row (``spatial.queries.width_classes``), so the
clouds below exercise narrow and full widths in one call. Results must be
those of brute force (all pairs, ``lexsort`` by distance then index) and
the distances those of SciPy's k-d tree; an undersized plan is reported
in the need, never silent."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from avblocks.utility import spatial as sp
from avblocks.utility.spatial.queries import (
    MAX_CLASSES,
    MIN_WIDTH,
    ONE_CHUNK_CLASSES,
    TRACED_CHUNK,
    width_classes,
)

jax = pytest.importorskip("jax")
jnp = jax.numpy


def brute(p, r, k):
    d = np.sqrt(((p[None, :, :] - p[:, None, :]) ** 2).sum(-1))
    n = len(p)
    ok = (d <= r) & ~np.eye(n, dtype=bool)
    dm = np.where(ok, d, np.inf)
    j = np.broadcast_to(np.arange(n), (n, n))
    o = np.lexsort((j, dm), axis=-1)[:, :k]
    return np.take_along_axis(np.where(ok, j, -1), o, 1), np.take_along_axis(dm, o, 1)


def kdtree_distances(p, r, k):
    """SciPy's k-d tree: the k nearest others within r (inclusive)."""
    d, _ = cKDTree(p).query(p, k=k + 1, distance_upper_bound=np.nextafter(r, np.inf))
    return d[:, 1:]                 # the point itself first (distance 0)


def one_cell(rng):
    return rng.uniform(0, 0.2, (300, 2))                # every point in one cell


def two_clusters(rng):
    return np.concatenate([rng.normal(0, 0.15, (600, 2)),
                           rng.normal(1000, 0.15, (600, 2)),
                           rng.uniform(-300, 300, (900, 2))])     # and a sparse field


def lattice_and_blob(rng):
    g = np.stack(np.meshgrid(np.arange(40.0), np.arange(40.0)), -1).reshape(-1, 2)
    return np.concatenate([g, 20.0 + np.round(rng.uniform(0, 0.5, (150, 2)) * 4) / 4])


@pytest.mark.parametrize("cloud", [one_cell, two_clusters, lattice_and_blob])
def test_crowded_clouds_equal_brute_force_and_the_kd_tree(cloud):
    p = cloud(np.random.default_rng(5))
    r, k = 1.0, 12
    with jax.enable_x64(True):
        plan = sp.plan_cells(p, r)
        i, d, need = jax.jit(lambda q: sp.nearest(plan, q, r, k, xp=jnp))(jnp.asarray(p))
    i, d = np.asarray(i), np.asarray(d)
    assert int(need.capacity) <= plan.capacity          # the plan held every row
    assert len(width_classes(plan.capacity)) > 1        # narrow widths were on offer
    bi, bd = brute(p, r, k)
    np.testing.assert_array_equal(i, bi)
    np.testing.assert_allclose(d, bd, rtol=1e-12)
    np.testing.assert_allclose(d, kdtree_distances(p, r, k), rtol=1e-12)
    # the same under vmap (one width there: the plan's)
    with jax.enable_x64(True):
        iv = jax.jit(jax.vmap(lambda q: sp.nearest(plan, q, r, k, xp=jnp)[0]))(
            jnp.asarray(np.stack([p, p[::-1]])))
    np.testing.assert_array_equal(np.asarray(iv[0]), bi)
    np.testing.assert_array_equal(np.asarray(iv[1]), brute(p[::-1], r, k)[0])


def test_many_chunks_take_their_own_widths_and_stay_exact():
    # a dense blob among sparse points, more rows than one chunk: the blob's
    # chunk needs the full width, the sparse chunks a quarter of it
    rng = np.random.default_rng(9)
    p = np.concatenate([rng.uniform(0, 400, (2 * TRACED_CHUNK, 2)),
                        rng.normal(200, 0.3, (200, 2))])
    r, k = 2.0, 8
    with jax.enable_x64(True):
        plan = sp.plan_cells(p, r)
        i, d, _ = jax.jit(lambda q: sp.nearest(plan, q, r, k, xp=jnp))(jnp.asarray(p))
    bi, bd = brute(p, r, k)
    np.testing.assert_array_equal(np.asarray(i), bi)
    np.testing.assert_allclose(np.asarray(d), bd, rtol=1e-12)


def test_an_undersized_plan_is_reported_not_silent():
    p = one_cell(np.random.default_rng(1))
    small = sp.CellList(1.0, capacity=64, hits=64)
    with jax.enable_x64(True):
        _, _, need = jax.jit(lambda q: sp.nearest(small, q, 1.0, 4, xp=jnp))(jnp.asarray(p))
    assert small.exceeded(need) and int(need.capacity) == len(p)


def test_width_classes():
    # halvings of the plan's capacity rounded up to multiples of 8, down to
    # MIN_WIDTH, at most MAX_CLASSES of them
    assert width_classes(256) == (16, 32, 64, 128, 256)
    assert width_classes(100) == (16, 32, 56, 100)
    assert width_classes(930) == (32, 64, 120, 240, 472, 930)   # six at most
    assert width_classes(40) == (16, 24, 40)
    assert width_classes(24) == (16, 24)           # a quarter would be below 16
    assert width_classes(16) == (16,)
    assert width_classes(9) == (9,)
    assert width_classes(930, ONE_CHUNK_CLASSES) == (240, 472, 930)   # one chunk
    for cap in range(1, 3000, 7):                  # each class holds at least half
        w = width_classes(cap)
        assert w[-1] == cap and len(w) <= MAX_CLASSES and list(w) == sorted(set(w))
        assert all(b <= 2 * a + 8 for a, b in zip(w, w[1:]))
        assert w[0] >= MIN_WIDTH or w == (cap,)


# ------------------------------------------------- within and candidates

def brute_within(p, r, box=None):
    """Independent truth: every other point within r (inclusive), all pairs."""
    d = p[None, :, :] - p[:, None, :]
    if box is not None:
        d = d - np.asarray(box) * np.round(d / np.asarray(box))
    dist = np.sqrt((d ** 2).sum(-1))
    ok = (dist <= r) & ~np.eye(len(p), dtype=bool)
    return [set(np.nonzero(ok[a])[0].tolist()) for a in range(len(p))], dist


def rows_as_sets(idx):
    return [set(int(j) for j in row if j >= 0) for row in np.asarray(idx)]


def kdtree_sets(p, r):
    """SciPy's k-d tree: the others within r (inclusive)."""
    tree = cKDTree(p)
    return [set(s) - {a} for a, s in enumerate(tree.query_ball_point(p, r))]


# smaller crowds than above: XLA's CPU compile of the radius search grows
# fast with the candidate width (a 450-wide plan took about a minute)

def one_cell_small(rng):
    return rng.uniform(0, 0.2, (90, 2))                 # every point in one cell


def two_clusters_small(rng):
    return np.concatenate([rng.normal(0, 0.15, (60, 2)), rng.normal(1000, 0.15, (60, 2)),
                           rng.uniform(-100, 100, (300, 2))])


def lattice_and_blob_small(rng):
    g = np.stack(np.meshgrid(np.arange(20.0), np.arange(20.0)), -1).reshape(-1, 2)
    return np.concatenate([g, 10.0 + np.round(rng.uniform(0, 0.5, (50, 2)) * 4) / 4])


SMALL = [one_cell_small, two_clusters_small, lattice_and_blob_small]


def cells_around(p, plan):
    """Independent truth for candidates: the points in the 5 x 5 cells around
    each point's own (edge reach / split), counted in Python integers."""
    e = plan.reach / plan.split
    c = np.floor(p / e).astype(np.int64)
    near = np.all(np.abs(c[None, :, :] - c[:, None, :]) <= plan.split, axis=-1)
    return [set(np.nonzero(near[a])[0].tolist()) for a in range(len(p))]


@pytest.mark.parametrize("cloud", SMALL)
def test_within_on_crowded_clouds_equals_brute_force_and_the_kd_tree(cloud):
    p = cloud(np.random.default_rng(6))
    r = 1.0
    with jax.enable_x64(True):
        plan = sp.plan_cells(p, r)
        i, d, need = jax.jit(lambda q: sp.within(plan, q, r, xp=jnp))(jnp.asarray(p))
    i, d = np.asarray(i), np.asarray(d)
    assert plan.exceeded(need) is None                  # the plan held every row
    assert len(width_classes(plan.capacity)) > 1        # narrow widths were on offer
    want, dist = brute_within(p, r)
    assert rows_as_sets(i) == want == kdtree_sets(p, r)
    ok = i >= 0
    rows = np.broadcast_to(np.arange(len(p))[:, None], i.shape)
    np.testing.assert_allclose(d[ok], dist[rows[ok], i[ok]], rtol=1e-12)
    assert np.all(np.isinf(d[~ok]))
    assert int(need.hits) == max(len(s) for s in want)
    if cloud is one_cell_small:         # the same under vmap (one width: the plan's)
        with jax.enable_x64(True):
            iv = jax.jit(jax.vmap(lambda q: sp.within(plan, q, r, xp=jnp)[0]))(
                jnp.asarray(np.stack([p, p[::-1]])))
        assert rows_as_sets(iv[0]) == want
        assert rows_as_sets(iv[1]) == brute_within(p[::-1], r)[0]


@pytest.mark.parametrize("cloud", SMALL)
def test_candidates_on_crowded_clouds_are_the_cells_around(cloud):
    p = cloud(np.random.default_rng(7))
    with jax.enable_x64(True):
        plan = sp.plan_cells(p, 1.0)
        c, need = jax.jit(lambda q: sp.candidates(plan, q, xp=jnp))(jnp.asarray(p))
    c = np.asarray(c)
    assert c.shape == (len(p), plan.capacity)
    want = cells_around(p, plan)
    assert rows_as_sets(c) == want
    assert int(need.capacity) == max(len(s) for s in want) <= plan.capacity
    # each row: its candidates first, then -1 only
    filled = c >= 0
    assert np.all(filled.sum(1) == [len(s) for s in want])
    assert np.all(np.diff(filled.astype(int), axis=1) <= 0)


def test_within_and_candidates_over_many_chunks_take_their_own_widths():
    rng = np.random.default_rng(9)
    p = np.concatenate([rng.uniform(0, 400, (2 * TRACED_CHUNK, 2)),
                        rng.normal(200, 0.3, (60, 2))])
    r = 2.0
    with jax.enable_x64(True):
        plan = sp.plan_cells(p, r)
        i, _, need = jax.jit(lambda q: sp.within(plan, q, r, xp=jnp))(jnp.asarray(p))
        c, _ = jax.jit(lambda q: sp.candidates(plan, q, xp=jnp))(jnp.asarray(p))
    assert plan.exceeded(need) is None
    assert rows_as_sets(i) == brute_within(p, r)[0] == kdtree_sets(p, r)
    assert rows_as_sets(c) == cells_around(p, plan)


def test_within_in_a_periodic_box_with_a_crowd():
    rng = np.random.default_rng(3)
    box = (20.0, 20.0)
    p = np.concatenate([rng.uniform(0, 20, (300, 2)),
                        np.mod(rng.normal(0, 0.2, (50, 2)), 20.0)])  # across the corner
    r = 1.5
    with jax.enable_x64(True):
        plan = sp.plan_cells(p, r, box=box)
        i, _, need = jax.jit(lambda q: sp.within(plan, q, r, xp=jnp))(jnp.asarray(p))
    assert plan.exceeded(need) is None and len(width_classes(plan.capacity)) > 1
    assert rows_as_sets(i) == brute_within(p, r, box)[0]


def test_an_undersized_within_plan_is_reported_not_silent():
    p = one_cell_small(np.random.default_rng(2))
    small = sp.CellList(1.0, capacity=32, hits=16)
    with jax.enable_x64(True):
        _, _, need = jax.jit(lambda q: sp.within(small, q, 1.0, xp=jnp))(jnp.asarray(p))
        _, cneed = jax.jit(lambda q: sp.candidates(small, q, xp=jnp))(jnp.asarray(p))
    msg = small.exceeded(need)
    assert msg and "capacity" in msg and "hits" in msg
    assert int(need.capacity) == int(cneed.capacity) == len(p)


def test_grad_through_within_on_a_crowd_equals_finite_differences():
    rng = np.random.default_rng(11)
    p = np.concatenate([rng.uniform(0, 30, (200, 2)), rng.normal(15, 0.4, (40, 2))])
    r = 1.0
    with jax.enable_x64(True):
        plan = sp.plan_cells(p, r)
        assert len(width_classes(plan.capacity)) > 1

        def cost(q):
            i, d, _ = sp.within(plan, q, r, xp=jnp)
            return jnp.sum(jnp.where(i >= 0, (r - d) ** 3, 0.0))

        g = np.asarray(jax.jit(jax.grad(cost))(jnp.asarray(p)))

    def c_np(q):                # all pairs, NumPy: an independent evaluation
        d = np.sqrt(((q[None] - q[:, None]) ** 2).sum(-1))
        ok = (d <= r) & ~np.eye(len(q), dtype=bool)
        return np.sum(np.where(ok, (r - d) ** 3, 0.0))
    h = 1e-6
    for a in [(0, 0), (7, 1), (205, 0), (230, 1)]:
        e = np.zeros_like(p)
        e[a] = h
        fd = (c_np(p + e) - c_np(p - e)) / (2 * h)
        assert g[a] == pytest.approx(fd, rel=1e-5, abs=1e-8)
