"""Row blocks (``utility.arrays.map_rows``, ``cache_rows``): a per-row
function over blocks of rows gives what it gives over all rows at once,
under NumPy and traced, with a ragged last block; blocks are chosen only
for a traced run on a CPU whose tables outgrow the cache."""

import numpy as np
import pytest

from avblocks.utility import arrays
from avblocks.utility.arrays import cache_rows, map_rows


def _per_row(a, b):
    # a row-wise function with two outputs of different trailing shapes
    return np.sqrt(a) * b[:, :1], (a * a).sum(axis=1)


@pytest.mark.parametrize("size", [None, 7, 50, 64])
def test_map_rows_numpy_equals_one_pass(size):
    rng = np.random.default_rng(0)
    a, b = rng.uniform(0, 2, (50, 3)), rng.normal(size=(50, 4))
    want = _per_row(a, b)
    got = map_rows(_per_row, [a, b], np, size)
    for g, w in zip(got, want):
        np.testing.assert_array_equal(g, w)


@pytest.mark.parametrize("size", [7, 10, 64])
def test_map_rows_traced_equals_one_pass(size):
    jax = pytest.importorskip("jax")
    jnp = jax.numpy

    def per_row(a, b):
        return jnp.sqrt(a) * b[:, :1], (a * a).sum(axis=1)

    rng = np.random.default_rng(1)
    a, b = rng.uniform(0, 2, (50, 3)), rng.normal(size=(50, 4))
    with jax.enable_x64(True):
        got = jax.jit(lambda a, b: map_rows(per_row, [a, b], jnp, size))(a, b)
    for g, w in zip(got, _per_row(a, b)):
        assert g.shape == w.shape                   # the padding of the last block cut off
        np.testing.assert_allclose(np.asarray(g), w, rtol=1e-15)


def test_cache_rows_only_for_big_tables_traced_on_a_cpu():
    jax = pytest.importorskip("jax")
    jnp = jax.numpy
    assert jax.default_backend() == "cpu"
    # 10^5 x 12 doubles = 9.2 MiB > 4 MiB: blocks of 384 KiB / 96 B = 4096 rows
    assert cache_rows(100_000, 12, np.float64, jnp) == 4096
    assert cache_rows(100_000, 12, np.float32, jnp) == 8192
    # 10^4 x 12 doubles = 0.9 MiB fits: one pass
    assert cache_rows(10_000, 12, np.float64, jnp) is None
    assert cache_rows(100_000, 12, np.float64, np) is None           # NumPy: its own blocks
    assert cache_rows(100_000, 12, np.float64, jnp, batched=True) is None   # vmap
    # a power of two below the budget
    rows = cache_rows(10 ** 6, 50, np.float64, jnp)
    assert rows == 512 and rows * 50 * 8 <= arrays.CACHE_BLOCK_BYTES < 2 * rows * 50 * 8


def test_cache_rows_leaves_an_accelerator_one_pass(monkeypatch):
    jax = pytest.importorskip("jax")
    monkeypatch.setattr(jax, "default_backend", lambda: "gpu")
    assert cache_rows(10 ** 6, 12, np.float64, jax.numpy) is None
