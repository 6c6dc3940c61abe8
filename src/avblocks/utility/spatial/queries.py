"""The queries of a cell-list search: candidates, all within a radius, the
k nearest (exact, ties by index), and planning a search from sample points."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ...core.errors import ParameterError
from ..arrays import batched as _batched
from ..arrays import map_rows
from .cells import CellList, Need
from .layout import _bounds, _gather_slots, _int_type, _query_cells, _windows, layout


def plan_cells(points, reach, *, capacity=None, headroom=1.5, box=None, table=None,
               min_capacity=8, hits=None, count_hits=True) -> CellList:
    """Plan a :class:`CellList` from sample positions (build time, NumPy).

    ``capacity`` defaults to ``max(min_capacity, ceil(headroom * most))``
    where ``most`` is the largest candidate count of a point at ``points``;
    ``hits`` likewise from the most points within ``reach`` of one point
    (``count_hits=False``: not counted, left None, for a search that never
    answers :func:`within`). Non-finite points raise a ``ParameterError``
    naming the first.
    """
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] not in (2, 3):
        raise ParameterError("points must be (N, 2) or (N, 3)", param="points",
                             found=pts.shape)
    bad = ~np.isfinite(pts).all(axis=1)
    if bad.any():
        i = int(np.argmax(bad))
        raise ParameterError("points to plan a search from must be finite",
                             param="points", expected="finite coordinates",
                             found=f"point {i}: {pts[i].tolist()}")
    base = CellList(reach, None, table, box, pts.shape[1])
    n = pts.shape[0]
    if base.brute:
        return CellList(base.reach, 1, table, base.box, base.dim,
                        max(1, n - 1) if hits is None else int(hits))
    if capacity is None:
        # the most candidates of a point: the points in its cell window
        most = _most_candidates(base, pts) if n else 0
        if most is None:                # a periodic box, or a sparse frame
            most = _prepare(base, pts, None, np)[3]
        capacity = max(int(min_capacity), int(math.ceil(float(headroom) * most)))
    if hits is None and count_hits:
        hits = max(int(min_capacity), int(math.ceil(float(headroom) * _most_hits(base, pts))))
    return CellList(base.reach, int(capacity), table, base.box, base.dim,
                    None if hits is None else int(hits))


def _most_candidates(cells, pts):
    """The most candidates of one of ``pts`` in free space: the points in
    the ``(2 split + 1)^D`` cells around its own, what :func:`_prepare`'s
    slot ranges count (the same number), found without them: a count per
    cell of the frame (a dense grid), summed over the window along each
    axis by running sums, the largest sum of an occupied cell. Contiguous
    passes over the grid instead of ``2 * 5^(D-1)`` scattered lookups per
    point (10^7 points: 13 s -> about 1 s on this 2-core machine). None in
    a periodic box or when the frame has more than ``4 N + 4096`` cells
    (sparse: the slot ranges serve)."""
    if cells.box is not None:
        return None
    n = pts.shape[0]
    c = np.floor(pts / np.asarray(cells.cell_edges())).astype(np.int64)
    c -= c.min(axis=0)
    dims = (c.max(axis=0) + 1).tolist()
    g = math.prod(int(x) for x in dims)
    if g > 4 * n + 4096:
        return None
    key = c[:, -1]
    for a in range(cells.dim - 2, -1, -1):      # key = c_0 + W_0 (c_1 + W_1 c_2)
        key = key * dims[a] + c[:, a]
    count = np.bincount(key, minlength=g).reshape(dims[::-1])
    s, box = cells.split, count
    w = 2 * s + 1
    for ax in range(cells.dim):                 # a window sum along each axis
        pad = [(0, 0)] * cells.dim
        pad[ax] = (s + 1, s)
        run = np.cumsum(np.pad(box, pad), axis=ax)
        hi = [slice(None)] * cells.dim
        lo = [slice(None)] * cells.dim
        hi[ax], lo[ax] = slice(w, None), slice(0, -w)
        box = run[tuple(hi)] - run[tuple(lo)]
    return int(box[count > 0].max())


def _most_hits(cells, pts):
    """The most other points within ``cells.reach`` (inclusive) of one of
    ``pts``: the ``within`` search's ``need.hits``, counted by SciPy's k-d
    tree on all cores (planning 10^7 points by the cell list's rows took
    minutes). The tree's own test may differ from ``within``'s ``d2 <=
    r^2`` by a rounding at the very edge, which moves a plan's headroom by
    one point at most; a run that needs more is caught all the same."""
    from scipy.spatial import cKDTree
    if pts.shape[0] < 2:
        return 0
    if cells.box is not None:
        b = np.asarray(cells.box, dtype=float)
        p = pts - b * np.floor(pts / b)
        tree = cKDTree(np.where(p >= b, 0.0, p), boxsize=b, balanced_tree=False,
                       compact_nodes=False)
        q = tree.data
    else:
        tree = cKDTree(pts, balanced_tree=False, compact_nodes=False)
        q = pts
    cnt = tree.query_ball_point(q, cells.reach, return_length=True, workers=-1)
    return int(np.max(cnt)) - 1                     # itself


# ---------------------------------------------------------------- internals


CHUNK = 4096

#: Query rows handled together in a traced search: smaller, so a chunk's
#: (candidates, rows) keys stay in cache over the k selection passes
#: (measured at N = 1e4, k = 12: 4096 rows 9.9 ms, 1024 rows 6.5-7.1 ms).
TRACED_CHUNK = 1024

#: Bytes of (rows, candidates) temporaries a traced search's chunk may take
#: on an accelerator (GPU, TPU). There a chunk is one set of kernels run
#: one chunk after another (``lax.map``), so CPU-sized chunks of 1024 rows
#: would leave a GPU idle between ~1,000 small launches per step at N =
#: 10^6; the chunk grows instead until its temporaries (about 16 arrays of
#: 8 bytes per candidate slot) reach this budget.
ACCEL_CHUNK_BYTES = 2 ** 31


def traced_rows(width):
    """Query rows per chunk of a traced search whose rows read ``width``
    candidate slots: :data:`TRACED_CHUNK` on a CPU (cache-sized), on an
    accelerator the largest power of two whose temporaries fit
    :data:`ACCEL_CHUNK_BYTES` (at least :data:`TRACED_CHUNK`). The platform
    is JAX's default backend, where the engine runs a program."""
    import jax
    if jax.default_backend() == "cpu":
        return TRACED_CHUNK
    rows = ACCEL_CHUNK_BYTES // (16 * 8 * max(1, int(width)))
    return max(TRACED_CHUNK, 1 << (max(1, int(rows)).bit_length() - 1))


class _Query(NamedTuple):
    """Per-query data of a search, rows in processing order."""

    q: tuple         # per axis: (Q,) query coordinates
    me: object       # (Q,) slot of the query point in the sorted order (self) or -1
    a: tuple         # per key range: (Q,) first slot in the sorted points
    b: tuple         # per key range: (Q,) end slot
    rows: object     # (Q,) query index of each processed row, or None (identity)
    span: object = 0.0   # see Need.span


def _rows(a, i, xp):
    """``a[i]`` for a 2-D ``a``: under JAX one 1-D gather per column (XLA's
    CPU gather of rows is an order of magnitude slower)."""
    if xp is np:
        return a[i]
    return xp.stack([a[:, c][i] for c in range(a.shape[1])], axis=1)


def _cols(a):
    return tuple(a[:, c] for c in range(a.shape[1]))


def _prepare(cells, points, queries, xp, *, exclude_self=True, ids=None):
    """Sort the points by cell and find every query's slot ranges.

    Returns ``(ps, order, query, cap)``: the coordinates (one (N,) array
    per axis) of the points in sorted order, the sorting permutation, a
    :class:`_Query` and the candidate width."""
    n = points.shape[0]
    it = _int_type(points, xp)
    if cells.brute:
        q = points if queries is None else queries
        qn = q.shape[0]
        me = xp.arange(qn, dtype=it) if (queries is None and exclude_self) else \
            xp.full((qn,), -1, dtype=it)
        if ids is not None:
            me = xp.asarray(ids).astype(it)
        z = xp.zeros((qn,), dtype=it)
        order = xp.arange(n, dtype=it)
        return _cols(points), order, _Query(_cols(q), me, (z,), (z + n,), None, 0.0), \
            max(n, 1)
    points = _replicated(points, xp)
    if queries is not None:
        queries = _replicated(queries, xp)
    lay = layout(cells, points, xp)
    ps = tuple(c[lay.order] for c in _cols(points))
    if queries is None:            # process the points in cell order (locality)
        q, qc, rows = ps, _rows(lay.coords, lay.order, xp), lay.order
        # row r is the point at slot r
        me = xp.arange(n, dtype=it) if exclude_self else xp.full((n,), -1, dtype=it)
    else:
        q, qc, rows = _cols(queries), _query_cells(cells, lay, queries, xp), None
        me = xp.full((queries.shape[0],), -1, dtype=it)
        if ids is not None:        # the slots of the given point indices
            ids = xp.asarray(ids).astype(it)
            inv = _inverse(lay.order, xp)
            me = xp.where(ids >= 0, inv[xp.clip(ids, 0, n - 1)], -1).astype(it)
    bounds = _bounds(cells, lay, _windows(cells, lay, qc, xp), xp,
                     batched=xp is not np and _batched([points]))
    cap = cells.capacity
    if cap is None:
        if xp is not np:
            raise ParameterError("a traced search needs a static capacity",
                                 param="capacity", hint="plan it with plan_cells()")
        cap = max(1, int(np.max(sum(b - a for a, b in bounds)))) if q[0].shape[0] else 1
    return ps, lay.order, _Query(q, me, tuple(a for a, _ in bounds),
                                 tuple(b for _, b in bounds), rows, lay.span), int(cap)


def _inverse(perm, xp):
    """The inverse of a permutation ``perm`` (N,)."""
    n = perm.shape[0]
    if xp is np:
        inv = np.empty(n, dtype=perm.dtype)
        inv[perm] = np.arange(n, dtype=perm.dtype)
        return inv
    return xp.zeros(n, dtype=perm.dtype).at[perm].set(xp.arange(n, dtype=perm.dtype))


def _chunk_rows(width, xp, batched):
    """Rows per chunk: NumPy's default (None), :data:`TRACED_CHUNK` under
    ``vmap`` (an ensemble's runs multiply every temporary, and the engine
    sizes its chunks of runs without counting the search's), else
    :func:`traced_rows`."""
    if xp is np:
        return None
    return TRACED_CHUNK if batched else traced_rows(width)


def _rowmap(fn, arrays, xp, size=None):
    """``fn`` over row chunks of ``arrays`` (all with Q leading rows),
    outputs concatenated (:func:`~avblocks.utility.arrays.map_rows`;
    ``size`` None: :data:`CHUNK` rows under NumPy, :data:`TRACED_CHUNK`
    traced)."""
    size = (CHUNK if xp is np else TRACED_CHUNK) if size is None else size
    return map_rows(fn, arrays, xp, size)


def _shard_map():
    """JAX's ``shard_map`` (``jax.shard_map``; ``jax.experimental`` before
    JAX 0.7), called without its replication checks (the row functions
    branch and loop on per-device values)."""
    import jax
    fn = getattr(jax, "shard_map", None)
    if fn is not None:
        return lambda f, mesh, ins, out: fn(f, mesh=mesh, in_specs=ins, out_specs=out,
                                            check_vma=False)
    from jax.experimental.shard_map import shard_map as old  # pragma: no cover
    return lambda f, mesh, ins, out: old(f, mesh=mesh, in_specs=ins, out_specs=out,
                                         check_rep=False)


def _sharding(xp, args=()):
    """``(mesh, axis)`` when a traced search runs in a run whose agents are
    split over devices (:func:`avblocks.core.diagnostics.sharded`), not
    under ``vmap``; else None."""
    if xp is np or (args and _batched(args)):
        return None
    from ...core import diagnostics
    return diagnostics.sharding()


def _replicated(a, xp):
    """``a`` (the searched points) laid out whole on every device of a
    sharded run: each device sorts all points by cell and reads its queries'
    candidates, its strip of space and the halo of cells around it, from
    them (one all-gather of the points a search; see :func:`_over_devices`)."""
    got = _sharding(xp)
    if got is None:
        return a
    import jax
    from jax.sharding import NamedSharding, PartitionSpec
    return jax.lax.with_sharding_constraint(a, NamedSharding(got[0], PartitionSpec()))


def _over_devices(fn, shared, args, xp):
    """``fn(shared, *args)`` for row arrays ``args`` (the queries in cell
    order, Q leading rows; outputs likewise) and ``shared`` (a tuple of what
    every row reads: the sorted points and their order, the radius). In a
    sharded run its rows are split over the devices: device ``d`` answers
    the ``d``-th block of ``Q / D`` rows, a contiguous run of the
    cell-sorted order, which is a strip of space (cell rows along the last
    axis), reading the candidates of its strip and of the cells around it
    (the halo) from ``shared``, whole on every device. The rows are padded
    to a multiple of the devices with empty queries (no candidate) and the
    padding dropped. Elsewhere ``fn(shared, *args)``."""
    got = _sharding(xp, args)
    if got is None:
        return fn(shared, *args)
    import jax
    from jax.sharding import PartitionSpec
    mesh, axis = got
    ndev = int(mesh.shape[axis])
    q = int(args[0].shape[0])
    pad = -q % ndev
    if pad:
        args = [xp.concatenate([a, xp.zeros((pad,) + tuple(a.shape[1:]), a.dtype)])
                for a in args]
    whole = jax.tree_util.tree_map(lambda _: PartitionSpec(), shared)
    specs = (whole,) + (PartitionSpec(axis),) * len(args)
    out = _shard_map()(fn, mesh, specs, PartitionSpec(axis))(shared, *args)
    if pad:
        out = jax.tree_util.tree_map(lambda o: o[:q], out)
    return out


def in_view(d, heading, fov, xp):
    """Which offsets ``d`` (per axis, (Q, C)) lie inside the field of view
    ``fov`` (full angle, rad) around each query's ``heading`` (Q,)."""
    rel = xp.arctan2(d[1], d[0]) - heading[:, None]
    rel = xp.abs(xp.mod(rel + np.pi, 2 * np.pi) - np.pi)
    return rel <= 0.5 * fov + 1e-12


def _chunk_fn(cells, ps, order, cap, radius, xp, *, fov=None):
    """Row function: the candidates of a chunk as slots of the sorted
    points (``order[slot]`` is the point index: taken by the caller, for
    all candidates or only the selected ones), whether each slot holds a
    candidate, whether it is a hit (radius, not self, field of view), the
    squared distances and each row's candidate count."""
    dim = len(ps)

    def hits(me, heading, *rest):
        q, ab = rest[:dim], rest[dim:]
        k = len(ab) // 2
        bounds = list(zip(ab[:k], ab[k:]))
        pos, ok, _ = _gather_slots(bounds, cap, xp)
        d = []
        for a in range(dim):
            da = ps[a][pos] - q[a][:, None]
            if cells.box is not None:
                da = da - cells.box[a] * xp.round(da / cells.box[a])
            d.append(da)
        d2 = d[0] * d[0]
        for a in range(1, dim):
            d2 = d2 + d[a] * d[a]
        cnt = sum(b - a for a, b in bounds)
        val = ok
        if radius is not None:
            r = xp.asarray(radius, dtype=d2.dtype)
            val = ok & (d2 <= r * r) & (pos != me[:, None])
            if fov is not None:
                val = val & in_view(d, heading, fov, xp)
        return pos, ok, val, d2, cnt

    return hits


def _unsort(rows, arrays, xp):
    """Put rows processed in ``rows`` order back into query order."""
    if rows is None:
        return arrays
    inv = _inverse(rows, xp)
    return [_rows(a, inv, xp) if a.ndim == 2 else a[inv] for a in arrays]


def _args(query, heading, xp):
    h = heading
    if h is None:
        h = xp.zeros(query.q[0].shape[0], dtype=query.q[0].dtype)
    elif query.rows is not None:
        h = h[query.rows]
    return [query.me, h, *query.q, *query.a, *query.b]


def compact(ok, cols, width, xp):
    """Move the valid entries of each row to its front: arrays (Q, width)
    of each of ``cols`` (first fill value given with it), and the largest
    count (the width needed)."""
    it = np.int64 if xp is np else cols[0][0].dtype
    cnt = xp.sum(ok, axis=1)
    need = xp.max(cnt) if ok.shape[1] else xp.asarray(0)
    if width is None:
        width = max(1, int(need))
    qn = ok.shape[0]
    dest = xp.cumsum(ok, axis=1) - 1
    outs = []
    if xp is np:
        r, c = np.nonzero(ok)
        dcol = dest[r, c]
        keep = dcol < width
        r, c, dcol = r[keep], c[keep], dcol[keep]
        for a, fill in cols:
            o = np.full((qn, width), fill, dtype=a.dtype)
            o[r, dcol] = a[r, c]
            outs.append(o)
        return outs, need
    dest = xp.where(ok, dest, width)
    rr = xp.broadcast_to(xp.arange(qn)[:, None], ok.shape)
    for a, fill in cols:
        o = xp.full((qn, width), fill, dtype=a.dtype)
        outs.append(o.at[rr, dest].set(a, mode="drop"))
    del it
    return outs, need


def k_smallest(d2, idx, k, xp, axis=1, nonneg=False):
    """The ``k`` smallest ``(d2, idx)`` pairs of each query, sorted: ``k``
    passes of a minimum (distance first, then the smaller index among
    equal distances), each removing what it took. Exact; O(k M) per query.
    ``idx`` (broadcast to ``d2``) must be unique per query where ``d2`` is
    finite. ``axis`` holds each query's candidates: 1 (a row per query,
    the default) or 0 (a column per query: each pass is then an elementwise
    minimum of query-long vectors, faster under XLA on a CPU). ``nonneg``:
    ``d2`` holds no negative number and no NaN, so a traced run may take
    the minima of its bits as integers (the same order, the same values;
    XLA's CPU backend sends float minima to YNNPACK, and the integer ones
    made a flocking ensemble 11-13 % faster). Returns ``(d2 (Q, k), idx
    (Q, k))``."""
    qn, w = (d2.shape[0], d2.shape[1]) if axis == 1 else (d2.shape[1], d2.shape[0])
    kk = min(int(k), w)
    big = np.iinfo(np.int64).max if np.dtype(idx.dtype).itemsize == 8 else \
        np.iinfo(np.int32).max
    minimum = _bits_min if (nonneg and xp is not np) else xp.min

    def spread(v):                      # a per-query vector against d2
        return v[:, None] if axis == 1 else v[None, :]
    od, oi = [], []
    for _ in range(kk):
        m = minimum(d2, axis=axis)
        j = xp.min(xp.where(d2 == spread(m), idx, big), axis=axis)
        od.append(m)
        oi.append(j)
        d2 = xp.where(idx == spread(j), xp.inf, d2)
    if kk == 0:
        return xp.zeros((qn, 0), dtype=d2.dtype), xp.zeros((qn, 0), dtype=idx.dtype)
    return xp.stack(od, axis=1), xp.stack(oi, axis=1)


def _bits_min(a, axis):
    """Traced: ``min(a, axis)`` of a float array without negatives or NaN,
    as the minimum of its bits read as integers (IEEE order). Differentiable
    as ``min`` is in JAX (the tangent of the minimum, shared among ties)."""
    global _BITS_MIN
    if _BITS_MIN is None:
        _BITS_MIN = _make_bits_min()
    return _BITS_MIN(a, axis)


_BITS_MIN = None


def _make_bits_min():
    import functools

    import jax
    lax, jnp = jax.lax, jax.numpy

    @functools.partial(jax.custom_jvp, nondiff_argnums=(1,))
    def bits_min(a, axis):
        it = np.int64 if np.dtype(a.dtype).itemsize == 8 else np.int32
        return lax.bitcast_convert_type(
            jnp.min(lax.bitcast_convert_type(a, it), axis=axis), a.dtype)

    @bits_min.defjvp
    def _jvp(axis, primals, tangents):
        (a,), (t,) = primals, tangents
        m = bits_min(a, axis)
        at = a == jnp.expand_dims(m, axis)
        share = jnp.sum(at, axis=axis).astype(a.dtype)
        return m, jnp.sum(jnp.where(at, t, 0.0), axis=axis) / share

    return bits_min


def _smallest_keyed(d2, idx, k, xp):
    """Traced: the ``k`` smallest ``(d2, idx)`` pairs of each row, as the
    ``k + 1`` smallest of one integer key per candidate
    (:func:`_tournament`): a rank of ``d2`` in the high bits, the
    candidate's column (unique in a row) in the low ``b = bit_length(W -
    1)`` bits. Returns ``(idx (Q, k), exact)``, ``-1`` where a row has
    fewer. The column, not ``idx``, in the low bits: fewer bits (10 for a
    row of a thousand candidates, against 17 for the slot of one of 10^5
    points), and the tournament reads each minimum's group from its key.
    The distances of the selected points are recomputed by the caller
    (same arithmetic, same values).

    The rank of ``d2`` is any function of it that never decreases, so the
    keys order like ``(d2, idx)`` unless two of a row's ``k + 1`` smallest
    keys have the same rank (equal distances included); then ``exact`` is
    False and the caller takes the exact passes of :func:`k_smallest`
    (if ``d2_a < d2_b`` but ``a`` is not taken before ``b``, they share a
    rank, and so does every key taken between them).

    - 64-bit (a float64 program): the bits of ``d2`` (a float >= 0 orders
      as its bits do) with the low ``b`` bits cleared: equal ranks only
      for distances within ``2^(b - 52)`` of each other (relative).
    - 32-bit (a float32 program, which has no 64-bit integers): the
      float32 bits would keep ``23 - b`` bits of the distance (13 for rows
      of a thousand: near-equal ranks in most rows, so most chunks would
      take the exact passes), so the rank is ``d2`` scaled to the row's largest
      finite ``d2`` in ``q = min(31 - b, 24)`` bits, ``floor(d2 / max d2 *
      (2^q - 2))``, a distance ``2^-q`` of the row's span apart from the next
      (``q = 21`` at a thousand candidates). In 2-D ``d2`` of points spread
      evenly is spread evenly, which such a fixed-point rank suits."""
    import jax
    qn, w = d2.shape
    b = max(1, int(w - 1).bit_length())
    kk = min(int(k), w)
    passes = min(kk + 1, w)
    wide = np.dtype(d2.dtype).itemsize == 8
    it = np.int64 if wide else np.int32
    low = it((1 << b) - 1)
    column = xp.arange(w, dtype=it)[None, :]
    if wide:
        bits = jax.lax.bitcast_convert_type(d2, np.int64)
        key = (bits & ~low) | column
        none = int(np.array(np.inf).view(np.int64)) & ~int(low)   # the rank of inf
    else:
        q = min(31 - b, 24)
        qmax = (1 << q) - 2                    # exact in float32 (q <= 24)
        fin = d2 < np.inf                      # NaN and inf: no candidate
        span = xp.max(xp.where(fin, d2, 0), axis=1, keepdims=True)
        # d2 / span <= 1 (no overflow, even for a subnormal span)
        r = xp.floor(xp.where(fin, d2, 0) / xp.where(span > 0, span, 1) * qmax)
        rank = xp.where(fin, xp.minimum(r, qmax), qmax + 1).astype(it)
        key = (rank << b) | column
        none = (qmax + 1) << b
    got = _tournament(key, passes, xp, col_bits=b)
    trunc = got & ~low
    finite = trunc < none
    exact = ~xp.any(finite[:, 1:] & (trunc[:, 1:] == trunc[:, :-1]))
    col = xp.where(finite[:, :kk], got[:, :kk] & low, 0)
    sel = xp.where(finite[:, :kk], xp.take_along_axis(idx, col, axis=1), -1)
    return sel.astype(idx.dtype), exact


def _group(w):
    """Candidates per group of :func:`_tournament` for rows of ``w``: a
    pick reads ``w / g`` group minima and one group of ``g``, least near
    ``g = sqrt(w)``; a power of two from 8 to 32. Measured on 1024 rows,
    13 smallest, XLA on this CPU: ``w = 50``: groups of 8 0.77 ms, of 16
    1.6 ms, 13 passes over the row 1.1 ms; ``w = 456``: 16 -> 2.7 ms, 32 ->
    2.7 ms, 8 -> 3.3 ms, passes 16-19 ms."""
    g = 1 << max(0, round(math.log2(math.sqrt(max(1, int(w))))))
    return min(32, max(8, g))


#: Rows of at most this many candidates take :func:`_tournament`'s passes
#: (each pass one fused minimum over the row, of the keys above the one the
#: last pass took), wider rows its groups. 98 chunks of 1024 rows, 13
#: smallest, XLA on this CPU: width 16 13 ms (groups: 27), 24 18 (43), 32
#: 24 (46), 40 69 (55), 64 121 (62).
PASSES_WIDTH = 32


def _slots(w):
    """Candidate slots a keyed row of width ``w`` reads: ``w`` rounded up to
    a whole number of :func:`_tournament`'s groups (the extra slots hold no
    candidate), so the tournament needs no padded copy of its keys (at
    width 472, 98 chunks: 84 ms a step)."""
    w = int(w)
    while w > PASSES_WIDTH and w % _group(w):
        w = -(-w // _group(w)) * _group(w)
    return w


def _tournament(key, m, xp, col_bits=None):
    """Traced: the ``m`` smallest of each row of ``key`` (Q, W) int64 or
    int32, keys unique within a row (equal keys count once), ascending:
    (Q, m).

    A tournament, not ``m`` passes over all ``W`` candidates: the row is cut
    into groups of :func:`_group` candidates, each group's minimum kept; a pass takes
    the smallest group minimum and replaces that group's minimum by its
    smallest key above the one taken (one group read). ``O(W + m (W / G +
    G))`` per row instead of ``O(m W)``; the same keys, exactly. Rows of
    at most :data:`PASSES_WIDTH` take ``m`` passes over the row instead.
    Pass ``j`` reads the row once and writes nothing: the smallest key
    above pass ``j - 1``'s (unique keys). ``col_bits``: the low bits of
    each key hold its column, so a pick's group is read from the key taken
    (no arg-minimum; the row's width is then best a multiple of
    ``_group(W)``, else it is padded).
    """
    top = key.dtype.type(np.iinfo(key.dtype).max)
    qn, w = key.shape
    group = _group(w)
    if w <= PASSES_WIDTH:               # few candidates: passes over the row
        kt = key.T
        if xp is np:
            got, v = [], None
            for _ in range(m):          # the smallest key above the last one taken
                v = xp.min(kt if v is None else xp.where(kt > v[None, :], kt, top), axis=0)
                got.append(v)
            return xp.stack(got, axis=1)
        # traced: the passes in a loop, so the keys are made once; unrolled,
        # XLA fused the keys' arithmetic and the transpose into every pass
        # (float32 keys: 55 of 124 ms a step at 10^5 flocking agents)
        import jax

        def one(j, c):
            got, v = c
            v = xp.min(xp.where(kt > v[None, :], kt, top), axis=0)
            return got.at[:, j].set(v), v
        first = xp.min(kt, axis=0)
        got = xp.zeros((qn, m), key.dtype).at[:, 0].set(first)
        return jax.lax.fori_loop(1, m, one, (got, first))[0]
    ng = -(-w // group)
    if ng * group > w:
        key = xp.concatenate([key, xp.full((qn, ng * group - w), top, key.dtype)], 1)
    key = key.reshape(qn, ng, group)
    gmin = xp.min(key, axis=2)                          # (Q, groups)
    gid = xp.arange(ng)[None, :]
    got = []
    for _ in range(m):
        v = xp.min(gmin, axis=1)
        if col_bits is None:
            j = xp.argmin(gmin, axis=1)
        else:                           # a spent row (all top) reads any group
            j = xp.minimum((v & key.dtype.type((1 << col_bits) - 1)) // group, ng - 1)
        got.append(v)
        grp = xp.take_along_axis(key, j[:, None, None], axis=1)[:, 0, :]
        nxt = xp.min(xp.where(grp > v[:, None], grp, top), axis=1)
        gmin = xp.where(gid == j[:, None], nxt[:, None], gmin)
    return xp.stack(got, axis=1)


def _smallest_np(d2, idx, k, n):
    """NumPy: the ``k`` smallest ``(d2, idx)`` pairs (indices, distances)
    by ``np.argpartition`` of the 64-bit keys of :func:`_smallest_keyed`, then
    a sort of ``k + 1``; rows with near-equal distances take the exact
    passes. ``-1`` / ``inf`` where fewer."""
    qn, w = d2.shape
    kk = min(int(k), w)
    if kk == 0:
        return np.zeros((qn, 0), np.int64), np.zeros((qn, 0))
    b = max(1, int(n - 1).bit_length())
    low = np.int64((1 << b) - 1)
    key = (d2.view(np.int64) & ~low) | idx.astype(np.int64)
    take = min(kk + 1, w)
    if take < w:
        cols = np.argpartition(key, take - 1, axis=1)[:, :take]
    else:
        cols = np.broadcast_to(np.arange(w), (qn, w))
    kc = np.take_along_axis(key, cols, 1)
    o = np.argsort(kc, axis=1)
    cols = np.take_along_axis(cols, o, 1)
    key = np.take_along_axis(kc, o, 1)
    trunc = key & ~low
    inf_bits = np.array(np.inf).view(np.int64) & ~low
    finite = trunc < inf_bits
    sel = np.where(finite[:, :kk], np.take_along_axis(idx, cols[:, :kk], 1), -1)
    od = np.where(finite[:, :kk], np.take_along_axis(d2, cols[:, :kk], 1), np.inf)
    bad = np.nonzero(np.any(finite[:, 1:] & (trunc[:, 1:] == trunc[:, :-1]), axis=1))[0]
    if bad.size:
        ed, ei = k_smallest(d2[bad], idx[bad], kk, np)
        sel[bad] = np.where(np.isfinite(ed), ei, -1)
        od[bad] = ed
    return sel, od


#: the narrowest width class of a traced search (candidates per row)
MIN_WIDTH = 16

#: the most width classes a traced search compiles (each is a branch of
#: the chunk's ``lax.switch``: a copy of the row function for XLA; three
#: more added 4.2 s to one search's compile at N = 10^4 and 30-40 s to the
#: flocking program's), and the most when all rows fit one chunk (a step's
#: one search: its narrow widths save little there)
MAX_CLASSES = 6
ONE_CHUNK_CLASSES = 3


def width_classes(cap, most=MAX_CLASSES):
    """Candidate widths a traced :func:`nearest`, :func:`within` or
    :func:`candidates` chooses from per chunk of rows (per step when the
    rows fit one chunk): ``cap``, then halvings of it (``cap / 2``, ``cap /
    4``, ... rounded up to multiples of 8), none below :data:`MIN_WIDTH`,
    at most ``most`` in all (ascending). A chunk takes the smallest that
    holds its most crowded row, so its work follows its own crowding, not
    the plan's worst point: within a factor of two of it, down to the
    smallest class.

    Why halvings all the way down: a plan is grown for the most crowded
    moment of a run, and a flock that contracts is sparse for most of it.
    Counted on the benchmark's flock (N = 10^5, 4 s, plan capacity 930,
    chunk maxima 25 at t0 up to 415 at the end, every 5th step): a chunk
    read 256 slots per row on average with the classes ``cap``, ``cap/2``,
    ``cap/4``, 108 with halvings down to 32, against 79 for the exact
    maxima. One search of the initial lattice at N = 10^4 (plan 906):
    17.7 -> 10.3 ms; its first compile 5.7 -> 9.9 s."""
    cap = int(cap)
    out = [cap]
    div = 2
    while len(out) < int(most):
        w = -(-cap // div)
        w = -(-w // 8) * 8
        if w < MIN_WIDTH or w >= out[-1]:
            break
        out.append(w)
        div *= 2
    return tuple(reversed(out))                 # strictly decreasing: no repeats


def _pad_cols(a, k, fill, xp):
    if a.shape[1] >= k:
        return a[:, :k]
    pad = xp.full((a.shape[0], k - a.shape[1]), fill, dtype=a.dtype)
    return xp.concatenate([a, pad], axis=1)


def _by_width(make_row, cells, cap, query, args, xp, shared):
    """:func:`_rowmap` of ``make_row(width, shared)`` (a row function that
    reads ``width`` candidate slots per row; ``shared`` the arrays every
    row reads, such as the sorted points, passed on explicitly so that a
    sharded run can place them: :func:`_over_devices`): traced, each chunk
    of rows (:func:`traced_rows`; the whole step when it has fewer rows)
    takes the smallest of the :func:`width_classes` of ``cap`` that holds
    its most crowded row (``lax.switch``), so crowding in one place or at
    one time does not widen every row of every step (at most
    :data:`ONE_CHUNK_CLASSES` classes when the rows fit one chunk); NumPy,
    under ``vmap`` and in an all-pairs search the one width ``cap``
    serves. Every row function must return the same shapes whatever its
    width."""
    batched = xp is not np and _batched(args)
    size = _chunk_rows(cap, xp, batched)
    widths = () if (xp is np or cells.brute) else width_classes(
        cap, MAX_CLASSES if query.q[0].shape[0] > size else ONE_CHUNK_CLASSES)
    if len(widths) <= 1 or batched:
        return _over_devices(lambda sh, *a: _rowmap(make_row(cap, sh), a, xp, size),
                             shared, args, xp)
    import jax
    nq = len(query.q)

    def body(sh, *a):
        rows = [make_row(w, sh) for w in widths]

        def pick(*a):
            nr = (len(a) - 2 - nq) // 2
            lo, hi = a[2 + nq:2 + nq + nr], a[2 + nq + nr:]
            most = xp.max(sum(h - l for l, h in zip(lo, hi)))
            c = sum((most > w).astype(np.int32) for w in widths[:-1])
            return jax.lax.switch(c, rows, *a)
        return _rowmap(pick, a, xp, size)
    return _over_devices(body, shared, args, xp)


def candidates(cells, points, queries=None, xp=np):
    """Candidate neighbours of each query point: ``(cand, need)``.

    ``cand`` is (Q, M) int point indices, ``-1`` where empty, ``M =
    capacity``; every point within ``cells.reach`` of a query point is in
    its row when ``need.capacity <= capacity``. ``queries`` defaults to
    ``points``. Traced, each chunk of rows gathers only the smallest width
    class (:func:`width_classes`) that holds its most crowded row and pads
    the rest of its rows with ``-1``.
    """
    ps, order, query, cap = _prepare(cells, points, queries, xp)

    def make_row(w, sh):
        ps, order = sh
        f = _chunk_fn(cells, ps, order, w, None, xp)

        def row(*args):
            pos, ok, _, _, cnt = f(*args)
            return _pad_cols(xp.where(ok, order[pos], -1), cap, -1, xp), cnt
        return row

    cand, cnt = _by_width(make_row, cells, cap, query, _args(query, None, xp), xp,
                          (ps, order))
    (cand,) = _unsort(query.rows, [cand], xp)
    return cand, Need(xp.max(cnt), xp.asarray(0.0), 0, query.span)


def displacement(cells, points, cand, queries=None, xp=np):
    """``p_cand - q`` (Q, M, D) by the minimum image in a periodic box."""
    q = points if queries is None else queries
    d = points[xp.maximum(cand, 0)] - q[:, None, :]
    if cells.box is not None:
        box = xp.asarray(cells.box, dtype=d.dtype)
        d = d - box * xp.round(d / box)
    return d


def within(cells, points, radius, queries=None, xp=np, *, exclude_self=True):
    """Every point within ``radius`` (inclusive) of each query point.

    Returns ``(idx, dist, need)``: (Q, H) indices (``-1`` where none; in
    no particular order) and their distances (``inf`` where none); ``H =
    cells.hits`` (NumPy without a plan: the largest count found). With
    ``queries`` None the query points are the points and ``exclude_self``
    drops each point from its own row. Traced, each chunk of rows scans
    only the smallest width class (:func:`width_classes`) of candidates
    that holds its most crowded row and compacts its hits to ``H``
    columns there.
    """
    ps, order, query, cap = _prepare(cells, points, queries, xp,
                                     exclude_self=exclude_self)
    args = _args(query, None, xp)
    batched = xp is not np and _batched(args)
    shared = (ps, order, radius if xp is np else xp.asarray(radius))
    if xp is np or cells.brute or len(width_classes(cap)) <= 1 or batched:
        # one width: the candidates of all rows, then one compaction
        def body(sh, *a):
            ps, order, radius = sh
            f = _chunk_fn(cells, ps, order, cap, radius, xp)

            def row(*args):
                pos, _, val, d2, cnt = f(*args)
                return order[pos], val, d2, cnt, xp.sum(val, axis=1)
            return _rowmap(row, a, xp, _chunk_rows(cap, xp, batched))

        idx, val, d2, cnt, nh = _over_devices(body, shared, args, xp)
        (ci, cd), _ = compact(val, [(idx, -1), (d2, np.inf)], cells.hits, xp)
    else:
        # a width per chunk: each chunk compacts its own rows
        if cells.hits is None:
            raise ParameterError("a traced search needs a static hits width",
                                 param="hits", hint="plan it with plan_cells()")

        def make_row(w, sh):
            ps, order, radius = sh
            f = _chunk_fn(cells, ps, order, w, radius, xp)

            def row(*args):
                pos, _, val, d2, cnt = f(*args)
                (ci, cd), _ = compact(val, [(pos, -1), (d2, np.inf)], cells.hits, xp)
                return xp.where(ci >= 0, order[xp.maximum(ci, 0)], -1), cd, cnt, \
                    xp.sum(val, axis=1)
            return row

        ci, cd, cnt, nh = _by_width(make_row, cells, cap, query, args, xp, shared)
    dist = xp.sqrt(cd)
    ci, dist = _unsort(query.rows, [ci, dist], xp)
    return ci, dist, Need(xp.max(cnt), xp.asarray(radius, dtype=dist.dtype), xp.max(nh),
                          query.span)


def nearest(cells, points, radius, k, queries=None, xp=np, *, heading=None,
            fov=None, exclude_self=True, ids=None):
    """The ``k`` nearest points within ``radius`` of each query point.

    Sorted by distance, ties by index. With ``heading`` (Q,) and ``fov``
    (full angle), only points whose bearing from the query point relative
    to its heading lies in ``[-fov/2, fov/2]`` count.

    ``ids`` (Q,): the point index of each query point, left out of its own
    row (for queries that are some of the points).

    Returns ``(idx, dist, need)``: (Q, k) int (``-1`` padded) and float
    (``inf`` padded).
    """
    ps, order, query, cap = _prepare(cells, points, queries, xp,
                                     exclude_self=exclude_self, ids=ids)
    k = int(k)

    n = points.shape[0]
    # the key holds a candidate's column in its row, not its point index:
    # any number of points (the index is gathered for the selected columns)
    keyed = xp is not np and k > 0 and not cells.brute

    def exact(d2, idx):
        od, oi = k_smallest(d2, idx, k, xp)
        fin = xp.isfinite(od)
        return xp.where(fin, oi, -1), od

    def make_row(w, sh):
        ps, order, radius = sh
        f = _chunk_fn(cells, ps, order, _slots(w) if keyed else w, radius, xp, fov=fov)
        return lambda *args: row(f, ps, order, *args)

    def row(f, ps, order, *args):
        pos, _, val, d2, cnt = f(*args)
        d2 = xp.where(val, d2, xp.inf)
        if xp is np and k > 0 and not cells.brute:
            oi, od = _smallest_np(d2, order[pos], k, n)
        elif keyed:
            import jax
            # selected by (distance, column in the row): the order of
            # (distance, index) wherever the k + 1 smallest distances differ,
            # and the exact passes where they may not; only the selected
            # columns are turned into slots and point indices
            sel, ok = _smallest_keyed(d2, pos, k, xp)
            got = sel >= 0
            safe = xp.where(got, sel, 0)
            me = args[2:2 + len(ps)]             # the query coordinates of the chunk
            dd = 0.0
            for a, c in enumerate(ps):
                da = c[safe] - me[a][:, None]
                if cells.box is not None:
                    da = da - cells.box[a] * xp.round(da / cells.box[a])
                dd = dd + da * da
            fast = (xp.where(got, order[safe], -1), xp.where(got, dd, xp.inf))
            oi, od = jax.lax.cond(ok, lambda: fast, lambda: exact(d2, order[pos]))
        else:
            oi, od = exact(d2, order[pos])
        fin = oi >= 0
        od = xp.where(fin, xp.sqrt(xp.where(fin, od, 1.0)), xp.inf)
        return _pad_cols(oi, k, -1, xp), _pad_cols(od, k, np.inf, xp), cnt

    shared = (ps, order, radius if xp is np else xp.asarray(radius))
    oi, od, cnt = _by_width(make_row, cells, cap, query, _args(query, heading, xp), xp,
                            shared)
    oi, od = _unsort(query.rows, [oi, od], xp)
    # nearest keeps no row of hits, so hits are no limit of it (need 0)
    return oi, od, Need(xp.max(cnt), xp.asarray(radius, dtype=od.dtype), 0, query.span)
