"""utility.arrays.fold (fused short reductions) equals the plain reductions;
scenarios._task.sort_rows / drop_diagonal equal a stable argsort / the
index of the others."""

import numpy as np
import pytest

from avblocks.scenarios._task import drop_diagonal, others_index, sort_rows
from avblocks.utility.arrays import fold, norm2


@pytest.mark.jax
@pytest.mark.parametrize("axis", [0, 1, 2, -1, -2])
def test_fold_equals_reductions(axis):
    jnp = pytest.importorskip("jax.numpy")
    x = np.random.default_rng(0).normal(size=(3, 7, 5)).astype(np.float32)
    x[0, 0, 0] = np.inf
    for op, red in ((jnp.minimum, np.min), (jnp.maximum, np.max), (jnp.add, np.sum)):
        np.testing.assert_allclose(fold(op, jnp.asarray(x), axis, jnp), red(x, axis=axis),
                                   rtol=1e-6)
        np.testing.assert_array_equal(fold(getattr(np, op.__name__), x, axis, np),
                                      red(x, axis=axis))
    k = (np.where(np.isinf(x), 0, x) * 10).astype(np.int32)
    np.testing.assert_array_equal(fold(jnp.add, jnp.asarray(k), axis, jnp),
                                  k.sum(axis=axis, dtype=np.int32))
    np.testing.assert_array_equal(fold(jnp.minimum, jnp.asarray(k), axis, jnp),
                                  k.min(axis=axis))


@pytest.mark.jax
@pytest.mark.parametrize("where", [0, 3, 6])
def test_fold_propagates_nan_as_min_does(where):
    jnp = pytest.importorskip("jax.numpy")
    x = np.arange(14.0).reshape(2, 7)
    x[0, where] = np.nan
    for op, red in ((jnp.minimum, np.min), (jnp.maximum, np.max), (jnp.add, np.sum)):
        got = np.asarray(fold(op, jnp.asarray(x), 1, jnp))
        np.testing.assert_array_equal(got, red(x, axis=1))      # NaN in row 0 only
        assert np.isnan(got[0]) and np.isfinite(got[1])


def test_norm2():
    v = np.array([[3.0, 4.0], [1.0, -2.0]])
    np.testing.assert_array_equal(norm2(v), [25.0, 5.0])


@pytest.mark.parametrize("n", [3, 4, 7])
def test_sort_rows_and_drop_diagonal(n):
    rng = np.random.default_rng(n)
    p = rng.normal(size=(5, n, 2))
    p[0, 1] = p[0, 0] + [0.3, 0.4]
    p[0, 2] = p[0, 0] - [0.4, 0.3]                               # a tie (same distance)
    rel = p[..., None, :, :] - p[..., :, None, :]                  # (5, n, n, 2)
    others = p[..., others_index(n), :] - p[..., :, None, :]       # (5, n, n-1, 2)
    np.testing.assert_array_equal(drop_diagonal(rel, np), others)
    key = np.where(np.eye(n, dtype=bool), np.inf, norm2(rel))
    got = sort_rows(key, [rel], np, slots=n - 1)[0]
    order = np.argsort(norm2(others), axis=-1, kind="stable")[..., None]
    np.testing.assert_array_equal(got, np.take_along_axis(others, order, axis=-2))
