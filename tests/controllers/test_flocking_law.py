"""flocking_law (the rearranged, blocked, traceable form) against Olfati-Saber's
equations written out agent by agent, pair by pair, with plain Python floats."""

import math

import numpy as np
import pytest

from avblocks.controllers import flocking as F


def _reference(q, p, idx, d, r, eps, a, b, h, c1, c2):
    """Algorithm 1 of Olfati-Saber (2006), eq. (23), one pair at a time,
    in math.* on floats (no arrays, no shared intermediates)."""
    def snorm(v):
        return (math.sqrt(1.0 + eps * sum(x * x for x in v)) - 1.0) / eps

    def rho(x):
        if x < h:
            return 1.0
        if x <= 1.0:
            return 0.5 * (1.0 + math.cos(math.pi * (x - h) / (1.0 - h)))
        return 0.0

    def phi(s):
        c = abs(a - b) / math.sqrt(4.0 * a * b)
        y = s + c
        return 0.5 * ((a + b) * y / math.sqrt(1.0 + y * y) + (a - b))

    r_a, d_a = snorm([r]), snorm([d])
    n, dim = q.shape
    out = np.zeros((n, dim))
    for i in range(n):
        for j in idx[i]:
            if j < 0:
                continue
            z = [float(q[j, m] - q[i, m]) for m in range(dim)]
            s = snorm(z)
            root = math.sqrt(1.0 + eps * sum(x * x for x in z))
            w = rho(s / r_a)
            for m in range(dim):
                out[i, m] += c1 * w * phi(s - d_a) * z[m] / root
                out[i, m] += c2 * w * float(p[j, m] - p[i, m])
    return out


def _cloud(rng, n, dim, d, r):
    q = rng.uniform(0, 2.5 * r, (n, dim))
    q[1] = q[0]                                   # a duplicate: sigma_eps(0) = 0
    q[3] = q[2]
    q[3, 0] += r                                  # exactly at the range
    q[5] = q[4]
    q[5, 0] += 0.2 * r                            # in the flat part of the bump
    p = rng.uniform(-1.5, 1.5, (n, dim))
    dist = np.linalg.norm(q[:, None] - q[None], axis=-1)
    k = 9
    idx = np.full((n, k), -1, dtype=np.int64)
    for i in range(n):
        # a superset of the agents within r (terms vanish beyond r) in any
        # order, shorter rows padded with -1
        js = [j for j in rng.permutation(n) if j != i and dist[i, j] <= 1.6 * r][:k - 1]
        idx[i, :len(js)] = js
    return q, p, idx


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("block", [None, 7])
def test_flocking_law_equals_algorithm_1_pair_by_pair(dim, block, monkeypatch):
    if block is not None:                         # NumPy cache blocks, a ragged last one
        monkeypatch.setattr(F, "NUMPY_BLOCK", block)
    rng = np.random.default_rng(3 + dim)
    d, r, eps, a, b, h, c1, c2 = 2.0, 2.6, 0.13, 3.0, 7.0, 0.3, 1.4, 0.6
    q, p, idx = _cloud(rng, 40, dim, d, r)
    want = _reference(q, p, idx, d, r, eps, a, b, h, c1, c2)
    got = F.flocking_law(q, p, idx, d, r, eps=eps, a=a, b=b, h=h, c1=c1, c2=c2)
    assert np.abs(want).max() > 1.0
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)


def test_flocking_block_with_gamma_equals_algorithm_2_and_reuses_the_padded_index():
    # Algorithm 2's navigational term added to eq. (23): u - c1g (q - q_r(t)) - c2g (p - p_r)
    rng = np.random.default_rng(8)
    n, d, r = 25, 1.5, 1.9
    q, p, idx = _cloud(rng, n, 2, d, r)
    target, tv, t = np.array([1.0, -2.0]), np.array([0.5, 0.25]), 3.7
    blk = F.Flocking(n, d, r=r, gamma=True, target=target, target_velocity=tv,
                     c1_gamma=0.3, c2_gamma=0.45)
    want = _reference(q, p, idx, d, r, 0.1, 5.0, 5.0, 0.2, 1.0, 1.0)
    want -= 0.3 * (q - (target + tv * t)) + 0.45 * (p - tv)
    from avblocks.core import memo
    m = memo.Memo()
    with memo.active(m):
        for _ in range(3):                        # RK4-like: the same neighbour array
            got = blk.output(t, {}, {"position": q, "velocity": p, "neighbors": idx},
                             np)["accel"]
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)
    assert m.misses == 1 and m.hits == 2          # flat pair list made once


@pytest.mark.parametrize("form", ["rows", "columns", "blocks"])
def test_flocking_law_traced_equals_numpy_and_its_gradient_is_finite(form, monkeypatch):
    jax = pytest.importorskip("jax")
    import jax.numpy as jnp

    from avblocks.utility import arrays
    # the neighbours gathered as rows (small tables) or column by column;
    # "blocks": the law in blocks of 8 agents (a large fleet on a CPU),
    # the last block ragged (30 agents)
    monkeypatch.setattr(F, "ROW_GATHER_BYTES", 1 << 30 if form == "rows" else 0)
    if form == "blocks":
        monkeypatch.setattr(arrays, "CACHE_TABLE_BYTES", 0)
        monkeypatch.setattr(arrays, "CACHE_BLOCK_BYTES", 8 * 9 * 8)
        assert arrays.cache_rows(30, 9, np.float64, jnp) == 8
    rng = np.random.default_rng(12)
    d, r = 2.0, 2.4
    q, p, idx = _cloud(rng, 30, 2, d, r)
    from avblocks.core.compiled._jax import x64
    with x64(True):
        law = jax.jit(lambda q, p: F.flocking_law(q, p, jnp.asarray(idx), d, r, xp=jnp))
        got = np.asarray(law(jnp.asarray(q), jnp.asarray(p)))
        np.testing.assert_allclose(got, F.flocking_law(q, p, idx, d, r), rtol=1e-12,
                                   atol=1e-12)
        np.testing.assert_allclose(got, _reference(q, p, idx, d, r, 0.1, 5.0, 5.0, 0.2,
                                                    1.0, 1.0), rtol=1e-12, atol=1e-12)
        # d/dp of sum(u . v) is linear in p: equals a central difference exactly
        v = rng.normal(size=q.shape)

        def cost(q, p):
            return jnp.sum(F.flocking_law(q, p, jnp.asarray(idx), d, r, xp=jnp) * v)

        gq, gp = jax.grad(cost, argnums=(0, 1))(jnp.asarray(q), jnp.asarray(p))
        assert np.all(np.isfinite(np.asarray(gq))) and np.all(np.isfinite(np.asarray(gp)))
        e = np.zeros_like(q)
        e[4, 1] = 1e-6
        fd = (F.flocking_law(q + e, p, idx, d, r) - F.flocking_law(q - e, p, idx, d, r))
        np.testing.assert_allclose(float(np.asarray(gq)[4, 1]), float((fd * v).sum() / 2e-6),
                                   rtol=1e-6)



def test_bump_polynomial_and_library_forms_agree():
    jnp = pytest.importorskip("jax.numpy")
    from avblocks.core.compiled._jax import x64
    w = np.linspace(0.0, np.pi / 2, 10001)
    want = np.array([2.0 * math.sin(x) ** 2 for x in w])
    np.testing.assert_allclose(F._two_sin_sq(w, np), want, rtol=0, atol=2e-15)
    with x64(True):
        poly = np.asarray(F._two_sin_sq(jnp.asarray(w), jnp))
    np.testing.assert_allclose(poly, want, rtol=0, atol=2e-15)
    assert poly[0] == 0.0 and F._two_sin_sq(np.zeros(1), np)[0] == 0.0   # beyond r: exactly 0


@pytest.mark.parametrize("block", [None, 4])
def test_flocking_law_agents_without_neighbours_get_zero(block, monkeypatch):
    # NumPy sums over the listed pairs only: empty rows and a block with no
    # pair at all (agents 4..7) give exactly 0; the rest as pair by pair
    if block is not None:
        monkeypatch.setattr(F, "NUMPY_BLOCK", block)
    rng = np.random.default_rng(21)
    q, p, idx = _cloud(rng, 12, 2, 2.0, 2.6)
    idx[4:8] = -1
    idx[1] = -1
    want = _reference(q, p, idx, 2.0, 2.6, 0.1, 5.0, 5.0, 0.2, 1.0, 1.0)
    got = F.flocking_law(q, p, idx, 2.0, 2.6)
    assert np.all(got[4:8] == 0.0) and np.all(got[1] == 0.0)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)
    none = F.flocking_law(q, p, np.full_like(idx, -1), 2.0, 2.6)
    assert none.shape == q.shape and np.all(none == 0.0)


@pytest.mark.parametrize("block", [None, 5])
def test_flocking_law_pairs_listed_once_twice_or_repeated(block, monkeypatch):
    # NumPy evaluates a pair listed both ways once for both agents; a pair
    # listed one way, or twice in one row, counts as listed (as pair by pair)
    if block is not None:
        monkeypatch.setattr(F, "NUMPY_BLOCK", block)
    rng = np.random.default_rng(5)
    q, p, idx = _cloud(rng, 16, 2, 2.0, 2.6)
    pairs = F._flat_pairs(idx)
    assert sum(b[-1] for b in pairs) > 0                    # some mirrored
    want = _reference(q, p, idx, 2.0, 2.6, 0.1, 5.0, 5.0, 0.2, 1.0, 1.0)
    np.testing.assert_allclose(F.flocking_law(q, p, idx, 2.0, 2.6), want,
                               rtol=1e-12, atol=1e-12)
    idx[3, -1] = idx[3, 0]                                  # j twice in row 3
    assert idx[3, 0] >= 0
    want = _reference(q, p, idx, 2.0, 2.6, 0.1, 5.0, 5.0, 0.2, 1.0, 1.0)
    np.testing.assert_allclose(F.flocking_law(q, p, idx, 2.0, 2.6), want,
                               rtol=1e-12, atol=1e-12)
