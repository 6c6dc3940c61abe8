"""The selection inside the traced k-nearest search: the tournament that
takes the smallest keys of a row (``spatial.queries._tournament``) against
NumPy's sort, and queries named by point index (``ids``: the search keys
candidates by their slot in the sorted points and must still leave each
query point out of its own row) against brute force."""

import numpy as np
import pytest

from avblocks.utility import spatial as sp
from avblocks.utility.spatial import queries as Q
from avblocks.utility.spatial.queries import (
    PASSES_WIDTH,
    _group,
    _slots,
    _smallest_keyed,
    _tournament,
)

jax = pytest.importorskip("jax")
jnp = jax.numpy
TOP = np.iinfo(np.int64).max


@pytest.mark.parametrize("width", [3, 16, 17, 32, 33, 50, 100, 257, 1100])
@pytest.mark.parametrize("m", [1, 13])
@pytest.mark.parametrize("bits", [64, 32])
def test_tournament_takes_the_smallest_keys_in_order(width, m, bits):
    """Against NumPy's sort; widths on both sides of the passes/tournament
    switch (``PASSES_WIDTH``) and groups of 8, 16 and 32; int64 keys (a
    float64 program) and int32 keys (a float32 program: no 64-bit types)."""
    assert PASSES_WIDTH == 32
    assert _group(50) == 8 and _group(456) == 16 and _group(1100) == 32
    rng = np.random.default_rng(width * 31 + m)
    rows = 70
    it = np.int64 if bits == 64 else np.int32
    top = np.iinfo(it).max
    # unique keys per row, from a narrow range so neighbours in value sit in
    # different groups; some rows with fewer real keys than m (top-padded)
    keys = np.stack([rng.choice(4 * width, width, replace=False) for _ in range(rows)])
    keys = keys.astype(it)
    keys[:10, 2:] = top
    want = np.sort(keys, axis=1)[:, :m]
    with jax.enable_x64(bits == 64):
        got = np.asarray(jax.jit(lambda k: _tournament(k, min(m, width), jnp))(keys))
    assert got.dtype == it
    real = want < top
    np.testing.assert_array_equal(got[:, :want.shape[1]][real], want[real])
    assert (got[:, :want.shape[1]][~real] == top).all()


def _lexsmallest(d2, k):
    """Columns of the ``k`` smallest ``(d2, column)`` of each row, ``-1``
    where a row has fewer finite distances: the exact order."""
    cols = np.lexsort((np.broadcast_to(np.arange(d2.shape[1]), d2.shape), d2), axis=1)[:, :k]
    return np.where(np.isfinite(np.take_along_axis(d2, cols, 1)), cols, -1)


@pytest.mark.parametrize("width", [12, 24, 32, 40, 56, 240, 1100])
def test_float32_keys_order_as_the_distances_or_say_not(width):
    """The 32-bit keys of a float32 program (a rank of ``d2`` scaled to the
    row's largest finite distance, then the column): each row (one call
    per row, so ``exact`` speaks for it) either selects the exact ``k``
    smallest ``(d2, column)`` or says it may not (``exact`` False), and says
    so only where two of its ``k + 1`` smallest distances are within the
    rank's resolution. Rows: distances spread evenly with some infinite
    (out of range), equal distances (a lattice), zeros, a far outlier that
    stretches the row's span, tiny spans (1e-33: ``2^q / span`` would
    overflow float32), nothing in range."""
    k = 12
    rng = np.random.default_rng(width)
    spread = (rng.uniform(0, 70, (300, width))).astype(np.float32)
    spread[rng.uniform(size=spread.shape) < 0.4] = np.inf
    ties = np.round(rng.uniform(0, 3, (20, width))).astype(np.float32) ** 2
    zeros = spread[:10].copy()
    zeros[:, :3] = 0.0
    outlier = spread[10:20].copy()
    outlier[:, -1] = 3.0e38
    tiny = (rng.uniform(0.1, 1, (10, width)) * 1e-33).astype(np.float32)
    empty = np.full((5, width), np.inf, np.float32)
    rows = np.concatenate([spread, ties, zeros, outlier, tiny, empty])
    idx = np.broadcast_to(np.arange(width, dtype=np.int32), (1, width)) * 3 + 7
    with jax.enable_x64(False):
        one = jax.jit(jax.vmap(lambda r: _smallest_keyed(r[None], jnp.asarray(idx), k, jnp)))
        sel, exact = (np.asarray(a) for a in one(jnp.asarray(rows)))
    sel = sel[:, 0]
    want = _lexsmallest(rows, min(k, width))
    want = np.where(want >= 0, want * 3 + 7, -1)
    np.testing.assert_array_equal(sel[exact][:, :want.shape[1]], want[exact])
    # not exact only where the k + 1 smallest finite distances come close
    srt = np.sort(rows, axis=1)[:, :k + 1].astype(np.float64)
    fin = np.isfinite(srt)
    top = np.max(np.where(np.isfinite(rows), rows, 0), axis=1, keepdims=True).astype(np.float64)
    with np.errstate(invalid="ignore"):                  # inf - inf past a row's end
        gap = np.diff(srt, axis=1) / np.where(top > 0, top, 1)
    close = np.any(fin[:, 1:] & (gap < 2.0 ** -(min(31 - (width - 1).bit_length(), 24) - 2)),
                   axis=1)
    assert not np.any(~exact & ~close)
    assert exact[:300].mean() > 0.9              # evenly spread rows are ranked
    assert not exact[300:320].any()              # a lattice's equal distances are not
    assert exact[-5:].all() and (sel[-5:] == -1).all()


def test_a_float32_search_by_keys_equals_its_exact_passes(monkeypatch):
    """Bit for bit (indices and distances): the traced k-nearest search of
    a float32 program by its keys against the same search made to take the
    exact passes everywhere; a random crowd (rows past the passes' width,
    in the tournament), a lattice (equal distances), a field of view, a
    periodic box, 3-D."""
    rng = np.random.default_rng(8)
    cloud = np.concatenate([rng.uniform(0, 40, (1500, 2)), 20 + rng.normal(0, 0.6, (500, 2))])
    grid = np.stack(np.meshgrid(np.arange(30.0), np.arange(30.0)), -1).reshape(-1, 2)
    cases = [("cloud", cloud, {}), ("lattice", grid, {}),
             ("fov", cloud, {"heading": rng.uniform(-3, 3, len(cloud)), "fov": 2.0}),
             ("box", cloud, {"box": (40.0, 40.0)}),
             ("3d", rng.uniform(0, 12, (2000, 3)), {})]
    r, k = 1.6, 9
    for name, p, kw in cases:
        box = kw.pop("box", None)
        plan = sp.plan_cells(p, r, box=box)
        heading = kw.pop("heading", None)

        def search(a, h, plan=plan, kw=kw):
            return sp.nearest(plan, a, r, k, xp=jnp, heading=h, **kw)[:2]
        args = (p.astype(np.float32), None if heading is None else heading.astype(np.float32))
        with jax.enable_x64(False):
            taken = []                               # each chunk's ``exact``, as run

            def keys(*a, taken=taken):
                sel, exact = _smallest_keyed(*a)
                jax.debug.callback(lambda e: taken.append(bool(e)), exact)
                return sel, exact
            with monkeypatch.context() as m:
                m.setattr(Q, "_smallest_keyed", keys)
                keyed = [np.asarray(a) for a in jax.jit(search)(*args)]
            jax.effects_barrier()
            assert taken, name                       # the keys were used
            if name != "lattice":                    # (equal distances: the passes)
                assert any(taken), name              # and their selection was kept
            with monkeypatch.context() as m:
                m.setattr(Q, "_smallest_keyed", lambda d2, idx, kk, xp: (
                    _smallest_keyed(d2, idx, kk, xp)[0], jnp.asarray(False)))
                exact = [np.asarray(a) for a in jax.jit(search)(*args)]
        assert keyed[1].dtype == np.float32, name
        np.testing.assert_array_equal(keyed[0], exact[0], err_msg=name)
        np.testing.assert_array_equal(keyed[1], exact[1], err_msg=name)
        assert (keyed[0] >= 0).sum() > len(p), name           # neighbours were found


@pytest.mark.parametrize("width", [40, 50, 240, 472, 480, 1100])
def test_tournament_reads_the_group_from_a_column_key(width):
    """Keys whose low bits hold their column (as the k-nearest search makes
    them): the group of each pick is read from the key, not searched for.
    Equal distances (high bits) in a row, rows that run out (keys of the
    infinite distance), a width that is not a whole number of groups (472:
    the tournament pads) and one that is (480, ``_slots``)."""
    b = (width - 1).bit_length()
    rng = np.random.default_rng(width)
    rows, m = 60, 13
    high = rng.integers(0, 40, (rows, width)).astype(np.int64)       # many ties
    high[:8, 5:] = np.array(np.inf).view(np.int64) >> b              # few finite
    keys = (high << b) | np.arange(width, dtype=np.int64)[None, :]
    want = np.sort(keys, axis=1)[:, :m]
    with jax.enable_x64(True):
        got = np.asarray(jax.jit(lambda k: _tournament(k, m, jnp, col_bits=b))(keys))
    np.testing.assert_array_equal(got, want)
    assert _slots(width) % _group(_slots(width)) == 0 and _slots(width) >= width


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


def test_an_accelerator_takes_big_chunks_with_the_same_results(monkeypatch):
    """On a GPU or TPU a chunk is a set of kernel launches, so the traced
    search sizes its chunks by a byte budget instead of the CPU's 1024 rows
    (``traced_rows``); the rows it returns do not depend on the chunking.
    The accelerator is stood in for by JAX's default-backend query: the
    arithmetic still runs on this CPU."""
    from avblocks.utility.spatial import queries as q
    assert q.traced_rows(80) == q.TRACED_CHUNK                  # a CPU here
    monkeypatch.setattr(jax, "default_backend", lambda: "gpu")
    assert q.traced_rows(80) == 1 << 17                          # 2 GiB / (128 B x 80)
    assert q.traced_rows(10 ** 6) == q.TRACED_CHUNK              # never below the CPU's
    monkeypatch.setattr(q, "ACCEL_CHUNK_BYTES", 128 * 40 * 2048)  # 2048 rows at width 40
    rng = np.random.default_rng(4)
    p = rng.uniform(0, 60, (5000, 2))
    r, k = 1.0, 7
    plan = sp.plan_cells(p, r)
    assert q.TRACED_CHUNK < q.traced_rows(plan.capacity) < len(p)   # several big chunks
    with jax.enable_x64(True):
        i, d, _ = jax.jit(lambda a: sp.nearest(plan, a, r, k, xp=jnp))(jnp.asarray(p))
    from scipy.spatial import cKDTree
    dd, ii = cKDTree(p).query(p, k=k + 1, distance_upper_bound=np.nextafter(r, np.inf))
    dd, ii = dd[:, 1:], np.where(np.isfinite(dd[:, 1:]), ii[:, 1:], -1)
    np.testing.assert_allclose(np.asarray(d), dd, rtol=1e-12)
    np.testing.assert_array_equal(np.asarray(i), ii)       # no ties in a random cloud


@pytest.mark.parametrize("spread", [False, True])
def test_slot_ranges_by_table_or_by_search_equal_the_kd_tree(spread):
    """Traced in free space the frame's cell count is data: a frame of at
    most ``4 N + 4096`` cells looks its slot ranges up in a table of cell
    starts, a larger one (``spread``: a few points far away) searches the
    sorted keys. Both give the k-d tree's neighbours."""
    from scipy.spatial import cKDTree

    from avblocks.utility.spatial.layout import layout
    rng = np.random.default_rng(6)
    p = rng.uniform(0, 60, (4000, 2))
    if spread:
        p[:3] = [[5000.0, 5000.0], [5000.5, 5000.0], [-3000.0, 20.0]]
    r, k = 1.0, 6
    plan = sp.plan_cells(p, r)
    frame = int(np.prod(np.asarray(layout(plan, p, np).dims)))
    assert (frame > 4 * len(p) + 4096) == spread          # the branch this case takes
    with jax.enable_x64(True):
        i, d, _ = jax.jit(lambda a: sp.nearest(plan, a, r, k, xp=jnp))(jnp.asarray(p))
        wi, wd, _ = jax.jit(lambda a: sp.within(plan, a, r, xp=jnp))(jnp.asarray(p))
    tree = cKDTree(p)
    dd, ii = tree.query(p, k=k + 1, distance_upper_bound=np.nextafter(r, np.inf))
    dd, ii = dd[:, 1:], np.where(np.isfinite(dd[:, 1:]), ii[:, 1:], -1)
    np.testing.assert_allclose(np.asarray(d), dd, rtol=1e-12)
    np.testing.assert_array_equal(np.asarray(i), ii)       # no ties in a random cloud
    want = [set(s) - {a} for a, s in enumerate(tree.query_ball_point(p, r))]
    assert [set(int(j) for j in row if j >= 0) for row in np.asarray(wi)] == want
