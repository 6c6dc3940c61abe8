"""The selection inside the traced k-nearest search: the tournament that
takes the smallest keys of a row (``spatial.queries._tournament``) against
NumPy's sort, and queries named by point index (``ids``: the search keys
candidates by their slot in the sorted points and must still leave each
query point out of its own row) against brute force."""

import numpy as np
import pytest

from avblocks.utility import spatial as sp
from avblocks.utility.spatial.queries import GROUP, _tournament

jax = pytest.importorskip("jax")
jnp = jax.numpy
TOP = np.iinfo(np.int64).max


@pytest.mark.parametrize("width", [3, 2 * GROUP, 2 * GROUP + 1, 100, 257])
@pytest.mark.parametrize("m", [1, 13])
def test_tournament_takes_the_smallest_keys_in_order(width, m):
    rng = np.random.default_rng(width * 31 + m)
    rows = 70
    # unique keys per row, from a narrow range so neighbours in value sit in
    # different groups; some rows with fewer real keys than m (TOP-padded)
    keys = np.stack([rng.choice(4 * width, width, replace=False) for _ in range(rows)])
    keys = keys.astype(np.int64)
    keys[:10, 2:] = TOP
    want = np.sort(keys, axis=1)[:, :m]
    with jax.enable_x64(True):
        got = np.asarray(jax.jit(lambda k: _tournament(k, min(m, width), jnp))(keys))
    real = want < TOP
    np.testing.assert_array_equal(got[:, :want.shape[1]][real], want[real])
    assert (got[:, :want.shape[1]][~real] == TOP).all()


def brute_ids(p, queries, ids, r, k):
    """k nearest of ``p`` within r (inclusive) of each query, its own point
    ``ids[i]`` left out: lexsort by distance, then index."""
    d = np.sqrt(((p[None, :, :] - queries[:, None, :]) ** 2).sum(-1))
    j = np.broadcast_to(np.arange(len(p)), d.shape)
    ok = (d <= r) & (j != ids[:, None])
    dm = np.where(ok, d, np.inf)
    o = np.lexsort((j, dm), axis=-1)[:, :k]
    return np.take_along_axis(np.where(ok, j, -1), o, 1), np.take_along_axis(dm, o, 1)


@pytest.mark.parametrize("xp", ["numpy", "jax"])
def test_queries_named_by_index_leave_themselves_out(xp):
    rng = np.random.default_rng(2)
    grid = np.stack(np.meshgrid(np.arange(12.0), np.arange(12.0)), -1).reshape(-1, 2)
    p = np.concatenate([grid, 5.0 + rng.uniform(0, 1, (200, 2))])   # ties and a crowd
    ids = rng.choice(len(p), 90, replace=False)
    q = p[ids]
    r, k = 1.5, 9
    bi, bd = brute_ids(p, q, ids, r, k)
    plan = sp.plan_cells(p, r)
    if xp == "numpy":
        i, d, _ = sp.nearest(plan, p, r, k, q, np, ids=ids)
    else:
        with jax.enable_x64(True):
            i, d, need = jax.jit(lambda a, b, c: sp.nearest(plan, a, r, k, b, jnp, ids=c))(
                jnp.asarray(p), jnp.asarray(q), jnp.asarray(ids))
        assert int(need.capacity) <= plan.capacity
    np.testing.assert_array_equal(np.asarray(i), bi)
    np.testing.assert_allclose(np.asarray(d), bd, rtol=1e-12)
