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
from avblocks.utility.spatial.queries import TRACED_CHUNK, width_classes

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
    assert width_classes(256) == (64, 128, 256)
    assert width_classes(100) == (32, 56, 100)
    assert width_classes(40) == (16, 24, 40)
    assert width_classes(24) == (16, 24)           # a quarter would be below 16
    assert width_classes(16) == (16,)
