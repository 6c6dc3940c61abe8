"""core.rng: Threefry-2x32 known answers, one stream under NumPy and jax.jit,
distributions (moments, KS) and independence of split keys."""

import numpy as np
import pytest
from scipy import stats

from avblocks.core import rng
from avblocks.core.compiled._jax import x64 as _x64

jax = pytest.importorskip("jax")
jnp = jax.numpy


# Random123 known-answer vectors for threefry2x32_20 (Salmon et al. 2011,
# kat_vectors; the same three appear in JAX's own Threefry tests)
KAT = [((0x00000000, 0x00000000), (0x00000000, 0x00000000), (0x6B200159, 0x99BA4EFE)),
       ((0xFFFFFFFF, 0xFFFFFFFF), (0xFFFFFFFF, 0xFFFFFFFF), (0x1CB996FC, 0xBB002BE7)),
       ((0x13198A2E, 0x03707344), (0x243F6A88, 0x85A308D3), (0xC4923A9C, 0x483DF7A0))]


@pytest.mark.parametrize("k, c, want", KAT)
def test_threefry_known_answers_numpy_and_jax(k, c, want):
    got = rng.threefry2x32(k[0], k[1], c[0], c[1], np)
    assert tuple(int(v) for v in got) == want
    f = jax.jit(lambda a, b: rng.threefry2x32(a[0], a[1], b[0], b[1], jnp))
    got = f(jnp.asarray(k, dtype=jnp.uint32), jnp.asarray(c, dtype=jnp.uint32))
    assert tuple(int(v) for v in got) == want


def _draws(k, xp):
    a, b, c = rng.split(k, xp, 3)
    return {"split": xp.stack([a, b, c]),
            "bits": xp.stack(rng.bits(a, (7, 3), xp)),
            "unit": rng.uniform(a, (50, 3), xp),
            "uniform": rng.uniform(a, (50, 3), xp, -2.0, 5.0),
            "normal": rng.normal(b, (101,), xp, 1.0, 2.0),
            "exponential": rng.exponential(c, (40,), xp, 0.5),
            "bernoulli": rng.bernoulli(a, (64,), xp, 0.3),
            "randint": rng.randint(b, (64,), xp, -3, 9)}


def test_numpy_and_jitted_jax_give_the_same_stream():
    with _x64(True):
        f = jax.jit(lambda kk: _draws(kk, jnp))
        for seed in (0, 1, 12345):
            k = rng.key(seed, "block.key")
            ref = _draws(k, np)
            got = f(jnp.asarray(k))
            for name in ("split", "bits", "bernoulli", "randint", "unit"):
                np.testing.assert_array_equal(np.asarray(got[name]), ref[name], err_msg=name)
            # libm vs XLA elementary functions (XLA log1p: ~20 ulp), fused multiply-add
            for name in ("uniform", "normal", "exponential"):
                np.testing.assert_allclose(np.asarray(got[name]), ref[name], rtol=1e-13,
                                           atol=1e-14, err_msg=name)
            # vmap over keys equals one call per key
        ks = np.stack(rng.split(k, np, 4))
        v = jax.vmap(lambda kk: rng.uniform(kk, (5,), jnp))(jnp.asarray(ks))
        for i in range(4):
            np.testing.assert_array_equal(np.asarray(v[i]), rng.uniform(ks[i], (5,), np))


def test_float32_uniform_uses_24_bits_in_both():
    with _x64(False):
        k = rng.key(5)
        u = np.asarray(jax.jit(lambda kk: rng.uniform(kk, (1000,), jnp))(jnp.asarray(k)))
    assert u.dtype == np.float32
    w0, _ = rng.bits(k, (1000,), np)
    np.testing.assert_array_equal(u, (w0 >> 8).astype(np.float32) * np.float32(2.0 ** -24))
    assert 0.0 <= u.min() and u.max() < 1.0


def test_uniform_bits_are_the_documented_53_bit_construction():
    k = rng.key(9)
    w0, w1 = rng.bits(k, (100,), np)
    want = ((w0 >> 5).astype(np.float64) * 2.0 ** 26 + (w1 >> 6)) / 2.0 ** 53
    np.testing.assert_array_equal(rng.uniform(k, (100,), np), want)


def test_distributions_moments_and_ks():
    n = 200_000
    k1, k2, k3, k4, k5 = rng.split(rng.key(2024), np, 5)
    u = rng.uniform(k1, (n,), np)
    assert 0.0 <= u.min() and u.max() < 1.0
    assert abs(u.mean() - 0.5) < 4 * np.sqrt(1 / 12 / n)
    assert abs(u.var() - 1 / 12) < 0.002
    assert stats.kstest(u[:20000], "uniform").pvalue > 1e-3
    z = rng.normal(k2, (n,), np)
    assert abs(z.mean()) < 4 / np.sqrt(n)
    assert abs(z.std() - 1.0) < 0.01
    assert abs(stats.skew(z)) < 0.03 and abs(stats.kurtosis(z)) < 0.06
    assert stats.kstest(z[:20000], "norm").pvalue > 1e-3
    e = rng.exponential(k3, (n,), np, 2.0)
    assert abs(e.mean() - 2.0) < 4 * 2.0 / np.sqrt(n)
    assert stats.kstest(e[:20000], stats.expon(scale=2.0).cdf).pvalue > 1e-3
    b = rng.bernoulli(k4, (n,), np, 0.3)
    assert abs(b.mean() - 0.3) < 4 * np.sqrt(0.21 / n)
    r = rng.randint(k5, (n,), np, -3, 9)
    assert r.min() == -3 and r.max() == 8
    counts = np.bincount(r + 3, minlength=12)
    assert stats.chisquare(counts).pvalue > 1e-3
    # the test has power: a shifted uniform is rejected
    assert stats.kstest(u[:20000] ** 1.05, "uniform").pvalue < 1e-3


def test_split_keys_are_independent():
    k = rng.key(7)
    keys = rng.split(k, np, 8)
    assert len({tuple(int(v) for v in kk) for kk in keys}) == 8
    a, b = rng.split(k, np)
    # the first two of a num=8 split are the num=2 split (counter-based)
    np.testing.assert_array_equal(a, keys[0])
    np.testing.assert_array_equal(b, keys[1])
    # draws from sibling keys and from the parent are uncorrelated
    n = 50_000
    xs = [rng.normal(kk, (n,), np) for kk in (k, *keys[:4])]
    c = np.corrcoef(np.stack(xs))
    off = c[~np.eye(len(xs), dtype=bool)]
    assert np.max(np.abs(off)) < 5 / np.sqrt(n)
    # split keys differ from the parent's own draws (separate counter word)
    w0, w1 = rng.bits(k, (2,), np)
    assert not np.array_equal(np.stack(keys[:2]), np.stack([w0, w1], axis=-1))
    # same key, same numbers; a neighbouring seed, other numbers
    np.testing.assert_array_equal(rng.uniform(k, (10,), np), rng.uniform(k, (10,), np))
    assert not np.allclose(rng.uniform(rng.key(8), (10,), np), rng.uniform(k, (10,), np))


def test_uniform_at_is_layout_free_and_matches_uniform():
    k = rng.key(11)
    u = rng.uniform(k, (6,), np)
    np.testing.assert_array_equal(rng.uniform_at(k, np.arange(6), 0, np), u)
    i = np.array([[3, 1], [0, 5]])
    j = np.array([[2, 2], [7, 1]])
    got = rng.uniform_at(k, i, j, np)
    for a in range(2):
        for b in range(2):
            assert got[a, b] == rng.uniform_at(k, i[a, b], j[a, b], np)
    with _x64(True):
        f = jax.jit(lambda kk, a, b: rng.uniform_at(kk, a, b, jnp))
        np.testing.assert_array_equal(np.asarray(f(jnp.asarray(k), i, j)), got)
