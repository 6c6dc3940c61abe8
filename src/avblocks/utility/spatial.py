r"""Neighbour search that traces: a sorted cell list with static shapes.

One implementation, written with the array namespace ``xp`` a block is
handed, serves the NumPy engine and the compiled (JAX) engine alike, under
``jit``, ``vmap`` and ``grad``.

Method
------
Space is cut into square (cubic) cells of edge ``>= reach / split``
(``split = 2``: a query point looks at the ``5^D`` cells around its own).
In free space the cells are numbered in a grid frame fitted to the points
(lowest occupied cell minus a border of ``split`` empty cells; its extent
is data, not shape), key ``c_0 + W_0 (c_1 + W_1 c_2)``; in a periodic box
the grid is the box's. The points are sorted by key once (stable: index
order within a cell). The ``2 split + 1`` cells of a row along axis 0 are
then one contiguous run of the sorted points, found by a binary search of
its first and end keys (or, when the grid is small, a table of cell
starts); a periodic row that wraps adds a second run. Each query point's
runs are concatenated into one row of ``capacity`` candidate slots
(:func:`candidates`). Every point within ``reach`` of the query point is
among them when the runs hold at most ``capacity`` points.

:func:`nearest` filters the candidates by radius (inclusive), self and
field of view, and takes the ``k`` smallest ``(distance, index)`` pairs by
``k`` passes of a row minimum: exact, ties broken by the smaller index, the
order of a brute-force ``lexsort((index, distance))``. Query rows are
handled in chunks of :data:`CHUNK` (``lax.map`` when traced), rows in cell
order for locality, so the temporaries stay ``O(CHUNK * capacity)``. Cost
per call: a sort of N keys, ``2 * 5^(D-1)`` binary searches per query,
``O(capacity * (D + k))`` per query. No (N, N) array is ever formed
(except with ``reach = inf``: every pair).

Under NumPy, :class:`NeighborSearch` answers radius queries with SciPy's
k-d tree (:func:`kd_nearest`: faster at every N measured here, see
``benchmarks/neighbors.py``), made exact on ties: a row whose ``k``-th
distance equals the farthest the tree returned is answered again by the
cell list. Both give the same neighbours in the same order.

Static shapes and overflow
--------------------------
``capacity`` (candidates per query point) and ``hits`` (width of
:func:`within`'s rows) are fixed when a :class:`CellList` is planned
(:func:`plan_cells`, from sample positions with ``headroom``, or given by
the user). Every search also returns what it *needed* (:class:`Need`: the
most candidates, the most hits, the largest radius asked for), so a
caller can tell, never silently, when the plan was too small. Under NumPy,
``capacity=None`` plans nothing: each call uses the count it finds.

Contract for block authors (the compiled engine relies on it)
--------------------------------------------------------------
A block that searches neighbours owns one :class:`NeighborSearch` per
search, created in its constructor::

    self.search = NeighborSearch(reach=radius, points="position")

``points`` names the block *input* whose first ``dim`` columns are the
positions searched; ``reach`` bounds the radius every call will use. The
block calls ``self.search.nearest(...)`` / ``within`` / ``candidates``
from its pure functions with the ``xp`` it is handed. The compiled engine
(:mod:`avblocks.core.compiled.plans`) finds the searches through the
block's ``searches()`` method when it has one (return them in a fixed
order), else through its attributes that are ``NeighborSearch`` objects;
before tracing it plans each from the block's input ``points`` at ``t0``
(a NumPy evaluation) unless the user fixed ``capacity=``, and after the
run it checks what the calls needed (re-plans and recompiles once, or
raises: ``compile(..., on_overflow=)``). A search used with queries other
than the points, or on positions computed inside the block, must still
name an input whose values at ``t0`` resemble the searched points, or be
given ``capacity=``.

Periodic boxes
--------------
With ``box=(L_x, L_y[, L_z])`` positions are taken modulo the box (origin at
0) and displacements by the minimum image, ``d - L round(d / L)``; ``reach``
must not exceed half the smallest box edge.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..core.errors import ParameterError


class Need(NamedTuple):
    """What a search needed: compare with the :class:`CellList`'s plan.

    ``capacity``: the most candidates one query point had (points in the
    cells around it; an int array scalar); ``reach``: the largest radius
    asked for (a float array scalar); ``hits``: the most points one query
    point had within the radius (0 when not counted); ``span``: the cells
    of the free-space frame over the cells its integer keys can address
    (above 1: the points are spread too far for the keys; in a traced
    float32 run, beyond about 46,000 cells per axis in 2-D).
    """

    capacity: object
    reach: object
    hits: object = 0
    span: object = 0.0


@dataclass(frozen=True)
class CellList:
    """The static plan of a cell-list search (structural: fixes shapes).

    Parameters
    ----------
    reach : float
        Cell edge lower bound: the largest radius a search may ask for.
        ``inf`` means "no range limit": searches compare every pair
        (O(N^2) work; use only for small N).
    capacity : int or None
        Most candidates per query point (points in the cells around it).
        ``None``: as many as found (NumPy only).
    table : int or None
        Accepted for compatibility; unused (the grid needs no hash table).
    box : tuple of float or None
        Periodic box edge lengths (origin at 0), or ``None`` (free space).
    dim : int
        2 or 3.
    hits : int or None
        Most points within the radius of one query point: the width of
        :func:`within`'s rows. ``None``: as many as found (NumPy only).
    split : int
        Cells per ``reach`` along an axis: a query point looks at ``2 split
        + 1`` cells per axis (finer cells: fewer candidates, more ranges).
    """

    reach: float
    capacity: int | None = None
    table: int | None = None
    box: tuple | None = None
    dim: int = 2
    hits: int | None = None
    split: int = 2

    def __post_init__(self):
        r = float(self.reach)
        if not r > 0:
            raise ParameterError("reach must be > 0", param="reach", expected="> 0",
                                 found=self.reach)
        if self.dim not in (2, 3):
            raise ParameterError("dim must be 2 or 3", param="dim", found=self.dim)
        for name in ("capacity", "hits"):
            v = getattr(self, name)
            if v is not None and int(v) < 1:
                raise ParameterError(f"{name} must be >= 1", param=name, expected=">= 1",
                                     found=v)
        if self.box is not None:
            box = tuple(float(b) for b in np.ravel(self.box))
            if len(box) != self.dim or not all(math.isfinite(b) and b > 0 for b in box):
                raise ParameterError("box must hold one positive length per axis",
                                     param="box", expected=f"{self.dim} lengths > 0",
                                     found=self.box)
            if r > 0.5 * min(box):
                raise ParameterError("reach must be at most half the smallest box edge",
                                     param="reach", expected=f"<= {0.5 * min(box)}",
                                     found=r)
            object.__setattr__(self, "box", box)
        object.__setattr__(self, "reach", r)

    @property
    def brute(self) -> bool:
        """True when every pair is compared (infinite reach)."""
        return not math.isfinite(self.reach)

    def cells_per_axis(self):
        """Cells along each axis of a periodic box (``None`` in free space)."""
        if self.box is None:
            return None
        return tuple(max(1, int(b // (self.reach / self.split))) for b in self.box)

    def cell_edges(self):
        """Edge length of a cell along each axis (``>= reach / split``)."""
        if self.box is None:
            return (self.reach / self.split,) * self.dim
        return tuple(b / c for b, c in zip(self.box, self.cells_per_axis()))

    def exceeded(self, need) -> str | None:
        """A sentence saying what ``need`` exceeds in this plan, or None."""
        cap = int(np.max(np.asarray(need.capacity)))
        hits = int(np.max(np.asarray(need.hits)))
        reach = float(np.max(np.asarray(need.reach)))
        msgs = []
        if self.capacity is not None and not self.brute and cap > self.capacity:
            msgs.append(f"capacity: a point had {cap} candidates around it, "
                        f"capacity is {self.capacity}")
        if self.hits is not None and hits > self.hits:
            msgs.append(f"hits: a point had {hits} others within range, "
                        f"room for {self.hits}")
        if reach > self.reach * (1 + 1e-6):        # float32 rounding of a radius is no overflow
            msgs.append(f"a search asked for radius {reach:g}, the cells were planned "
                        f"for {self.reach:g}")
        span = float(np.max(np.asarray(getattr(need, "span", 0.0))))
        if span > 1.0:
            msgs.append(f"span: the points spread over {span:.3g} times the cells the "
                        "integer cell keys address (run in float64, or use a periodic "
                        "box=)")
        return "; ".join(msgs) or None

    def grown(self, need, headroom=1.5) -> CellList:
        """This plan with room for ``need`` (times ``headroom``)."""
        cap = int(np.max(np.asarray(need.capacity)))
        hits = int(np.max(np.asarray(need.hits)))
        new_cap = self.capacity
        if self.capacity is not None and cap > self.capacity:
            new_cap = int(math.ceil(headroom * cap))
        new_hits = self.hits
        if self.hits is not None and hits > self.hits:
            new_hits = int(math.ceil(headroom * hits))
        if new_cap != self.capacity and new_hits is not None:
            # the hits counted were cut short by the candidates: allow for all
            new_hits = max(new_hits, new_cap)
        return CellList(self.reach, new_cap, self.table, self.box, self.dim, new_hits,
                        self.split)


def plan_cells(points, reach, *, capacity=None, headroom=1.5, box=None, table=None,
               min_capacity=8, hits=None) -> CellList:
    """Plan a :class:`CellList` from sample positions (build time, NumPy).

    ``capacity`` defaults to ``max(min_capacity, ceil(headroom * most))``
    where ``most`` is the largest candidate count of a point at ``points``;
    ``hits`` likewise from the most points within ``reach`` of one point.
    """
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] not in (2, 3):
        raise ParameterError("points must be (N, 2) or (N, 3)", param="points",
                             found=pts.shape)
    base = CellList(reach, None, table, box, pts.shape[1])
    n = pts.shape[0]
    if base.brute:
        return CellList(base.reach, 1, table, base.box, base.dim,
                        max(1, n - 1) if hits is None else int(hits))
    if capacity is None or hits is None:
        _, _, need = within(base, pts, base.reach, None, np)
        if capacity is None:
            capacity = max(int(min_capacity),
                           int(math.ceil(float(headroom) * int(need.capacity))))
        if hits is None:
            hits = max(int(min_capacity), int(math.ceil(float(headroom) * int(need.hits))))
    return CellList(base.reach, int(capacity), table, base.box, base.dim, int(hits))


# ---------------------------------------------------------------- internals
def _int_type(points, xp):
    """Integer type of cell keys: 64-bit unless a traced run is 32-bit."""
    if xp is np or np.dtype(points.dtype).itemsize == 8:
        return np.int64
    return np.int32


def _sort(keys, xp, cells=None):
    """Stable argsort of cell keys ``>= 0`` below ``cells`` (an int or an
    array scalar). Traced with 64-bit keys: one plain sort of ``key * N +
    index`` (XLA's CPU sort of one operand is ~4x faster than its sort of
    (key, index) pairs), taken when ``cells * N < 2^62``, else the argsort."""
    if xp is np:
        return np.argsort(keys, kind="stable")
    n = keys.shape[0]
    if np.dtype(keys.dtype).itemsize != 8 or cells is None or n < 2:
        return xp.argsort(keys, stable=True)
    import jax

    def packed():
        return xp.sort(keys * n + xp.arange(n, dtype=keys.dtype)) % n

    fits = cells * float(n) < 2.0 ** 62
    return jax.lax.cond(fits, packed, lambda: xp.argsort(keys, stable=True))


class _Layout(NamedTuple):
    """Points sorted by cell (see :func:`layout`)."""

    order: object      # (N,) point indices sorted by cell key (stable)
    skey: object       # (N,) sorted cell keys
    coords: object     # (N, D) cell coordinates of the points (grid frame)
    shift: object      # (D,) grid frame origin in cells (free space) or None
    dims: object       # (D,) cells per axis of the grid frame
    strides: tuple     # key strides per axis (array scalars)
    span: object       # frame cells / addressable keys (see Need.span)


def _cells_of(cells, pos, xp, it):
    edges = xp.asarray(cells.cell_edges(), dtype=pos.dtype)
    if cells.box is not None:
        box = xp.asarray(cells.box, dtype=pos.dtype)
        pos = pos - box * xp.floor(pos / box)
        ncell = xp.asarray(cells.cells_per_axis(), dtype=it)
        return xp.clip(xp.floor(pos / edges).astype(it), 0, ncell - 1)
    return xp.floor(pos / edges).astype(it)


def layout(cells, points, xp=np):
    """Sort ``points`` by cell: a :class:`_Layout`.

    Free space: cell coordinates are taken relative to the lowest occupied
    cell minus one, so the grid frame has an empty border layer on every
    side; cell ``(c_0, c_1[, c_2])`` has key ``c_0 + W_0 (c_1 + W_1 c_2)``
    (the frame's extent ``W`` is data, not shape). Periodic box: the grid
    is the box's (static) cells.
    """
    it = _int_type(points, xp)
    c = _cells_of(cells, points, xp, it)
    if cells.box is not None:
        shift = None
        dims = xp.asarray(cells.cells_per_axis(), dtype=it)
    else:
        shift = xp.min(c, axis=0) - cells.split
        c = c - shift
        dims = xp.max(c, axis=0) + cells.split + 1
    strides = [xp.asarray(1, dtype=it)]
    for a in range(1, cells.dim):
        strides.append(strides[-1] * dims[a - 1])
    key = c[:, 0]
    for a in range(1, cells.dim):
        key = key + c[:, a] * strides[a]
    g = dims[0].astype(float)                  # cells in the frame (float: no overflow)
    for a in range(1, cells.dim):
        g = g * dims[a].astype(float)
    order = _sort(key, xp, g)
    span = g / float(np.iinfo(it).max)
    return _Layout(order, key[order], c, shift, dims, tuple(strides), span)


def _query_cells(cells, lay, queries, xp):
    it = lay.coords.dtype
    c = _cells_of(cells, queries, xp, it)
    if lay.shift is None:
        return c
    return xp.clip(c - lay.shift, 0, lay.dims - 1)


def _windows(cells, lay, qc, xp):
    """Key ranges ``[lo, hi)`` (each (Q,)) covering the cells around each query.

    One contiguous range per row of cells (``2 split + 1`` cells along axis
    0; in a periodic box a row that wraps adds a second range)."""
    d, s = cells.dim, cells.split
    ncell = cells.cells_per_axis()
    whole = [ncell is not None and ncell[a] <= 2 * s + 1 for a in range(d)]
    per_axis = []
    for a in range(1, d):
        per_axis.append(tuple(range(ncell[a])) if whole[a] else tuple(range(-s, s + 1)))
    out = []
    q0 = qc[:, 0]
    for r in itertools.product(*per_axis):
        row = 0
        for a in range(1, d):
            if whole[a]:
                ca = xp.full_like(q0, r[a - 1])
            elif ncell is not None:
                ca = xp.mod(qc[:, a] + r[a - 1], ncell[a])
            else:
                ca = qc[:, a] + r[a - 1]
            row = row + ca * lay.strides[a]
        if ncell is None:
            out.append((row + q0 - s, row + q0 + s + 1))
        elif whole[0]:
            out.append((row + 0 * q0, row + ncell[0]))
        else:
            n0 = ncell[0]
            out.append((row + xp.maximum(q0 - s, 0),
                        row + xp.minimum(q0 + s, n0 - 1) + 1))
            under = xp.minimum(q0 - s, 0)               # -(cells wrapped below 0)
            over = xp.maximum(q0 + s - (n0 - 1), 0)     # cells wrapped past the end
            lo = xp.where(under < 0, row + n0 + under, row)
            hi = xp.where(under < 0, row + n0, row + over)
            out.append((lo, hi))
    return out


def _bounds(cells, lay, wins, xp):
    """Slots ``[a, b)`` in the sorted order of each key range."""
    n = lay.skey.shape[0]
    g = None
    if cells.box is not None:
        g = int(np.prod(cells.cells_per_axis()))
    elif xp is np:
        g = 1
        for x in np.asarray(lay.dims).tolist():
            g *= int(x)                               # Python int: no overflow
    if g is not None and g <= 4 * n + 4096:          # dense table of cell starts
        it = lay.skey.dtype
        if xp is np:
            count = np.bincount(lay.skey, minlength=g)
        else:
            count = xp.bincount(lay.skey, length=g)
        start = xp.concatenate([xp.zeros(1, dtype=it), xp.cumsum(count).astype(it)])
        return [(start[xp.clip(lo, 0, g)], start[xp.clip(hi, 0, g)]) for lo, hi in wins]
    out = []
    for lo, hi in wins:
        out.append((xp.searchsorted(lay.skey, lo, side="left"),
                    xp.searchsorted(lay.skey, hi, side="left")))
    return out


def _gather_slots(bounds, cap, xp):
    """(Q, cap) slots of the concatenated ranges, a validity mask, and the
    largest total a query needed."""
    a0, b0 = bounds[0]
    it = a0.dtype
    s = xp.arange(cap, dtype=it)[None, :]
    pos = a0[:, None] + s
    end = b0 - a0
    for a, b in bounds[1:]:
        e = end[:, None]
        pos = xp.where(s >= e, a[:, None] + (s - e), pos)
        end = end + (b - a)
    ok = s < end[:, None]
    return xp.where(ok, pos, 0), ok, xp.max(end)


#: Query rows handled together (bounds the (rows, candidates) temporaries).
CHUNK = 4096


class _Query(NamedTuple):
    """Per-query data of a search, rows in processing order."""

    q: tuple         # per axis: (Q,) query coordinates
    me: object       # (Q,) point index of the query (self) or -1
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
    lay = layout(cells, points, xp)
    ps = tuple(c[lay.order] for c in _cols(points))
    if queries is None:            # process the points in cell order (locality)
        q, qc, rows = ps, _rows(lay.coords, lay.order, xp), lay.order
        me = rows.astype(it) if exclude_self else xp.full((n,), -1, dtype=it)
    else:
        q, qc, rows = _cols(queries), _query_cells(cells, lay, queries, xp), None
        me = xp.full((queries.shape[0],), -1, dtype=it) if ids is None else \
            xp.asarray(ids).astype(it)
    bounds = _bounds(cells, lay, _windows(cells, lay, qc, xp), xp)
    cap = cells.capacity
    if cap is None:
        if xp is not np:
            raise ParameterError("a traced search needs a static capacity",
                                 param="capacity", hint="plan it with plan_cells()")
        cap = max(1, int(np.max(sum(b - a for a, b in bounds)))) if q[0].shape[0] else 1
    return ps, lay.order, _Query(q, me, tuple(a for a, _ in bounds),
                                 tuple(b for _, b in bounds), rows, lay.span), int(cap)


def _rowmap(fn, arrays, xp, size=None):
    """``fn`` over row chunks of ``arrays`` (all with Q leading rows),
    outputs concatenated: a Python loop of a few chunks under NumPy,
    ``lax.map`` when traced."""
    size = CHUNK if size is None else size
    qn = arrays[0].shape[0]
    if qn <= size:
        return fn(*arrays)
    if xp is np:
        outs = [fn(*[x[i:i + size] for x in arrays]) for i in range(0, qn, size)]
        return tuple(np.concatenate(parts, axis=0) for parts in zip(*outs))
    import jax
    m = -(-qn // size)
    pad = m * size - qn

    def fold(x):
        if pad:
            x = xp.concatenate([x, xp.broadcast_to(x[-1:], (pad,) + x.shape[1:])], 0)
        return x.reshape((m, size) + x.shape[1:])

    outs = jax.lax.map(lambda xs: fn(*xs), [fold(x) for x in arrays])
    return tuple(o.reshape((m * size,) + o.shape[2:])[:qn] for o in outs)


def _chunk_fn(cells, ps, order, cap, radius, xp, *, fov=None):
    """Row function: candidates, squared distances and validity of a chunk."""
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
        idx = order[pos]
        d2 = d[0] * d[0]
        for a in range(1, dim):
            d2 = d2 + d[a] * d[a]
        cnt = sum(b - a for a, b in bounds)
        val = ok
        if radius is not None:
            r = xp.asarray(radius, dtype=d2.dtype)
            val = ok & (d2 <= r * r) & (idx != me[:, None])
            if fov is not None:
                rel = xp.arctan2(d[1], d[0]) - heading[:, None]
                rel = xp.abs(xp.mod(rel + np.pi, 2 * np.pi) - np.pi)
                val = val & (rel <= 0.5 * fov + 1e-12)
        return idx, ok, val, d2, cnt

    return hits


def _unsort(rows, arrays, xp):
    """Put rows processed in ``rows`` order back into query order."""
    if rows is None:
        return arrays
    n = rows.shape[0]
    if xp is np:
        inv = np.empty(n, dtype=rows.dtype)
        inv[rows] = np.arange(n, dtype=rows.dtype)
    else:
        inv = xp.zeros(n, dtype=rows.dtype).at[rows].set(xp.arange(n, dtype=rows.dtype))
    return [_rows(a, inv, xp) if a.ndim == 2 else a[inv] for a in arrays]


def _args(query, heading, xp):
    h = heading
    if h is None:
        h = xp.zeros(query.q[0].shape[0], dtype=query.q[0].dtype)
    elif query.rows is not None:
        h = h[query.rows]
    return [query.me, h, *query.q, *query.a, *query.b]


def _compact(ok, cols, width, xp):
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


def _smallest(d2, idx, k, xp):
    """The ``k`` smallest ``(d2, idx)`` pairs of each row, sorted: ``k``
    passes of a row minimum (distance first, then the smaller index among
    equal distances), each removing what it took. Exact; O(k M) per row.
    ``idx`` entries must be unique per row where ``d2`` is finite."""
    qn, w = d2.shape
    kk = min(int(k), w)
    big = np.iinfo(np.int64).max if np.dtype(idx.dtype).itemsize == 8 else \
        np.iinfo(np.int32).max
    od, oi = [], []
    for _ in range(kk):
        m = xp.min(d2, axis=1)
        j = xp.min(xp.where(d2 == m[:, None], idx, big), axis=1)
        od.append(m)
        oi.append(j)
        d2 = xp.where(idx == j[:, None], xp.inf, d2)
    if kk == 0:
        return xp.zeros((qn, 0), dtype=d2.dtype), xp.zeros((qn, 0), dtype=idx.dtype)
    return xp.stack(od, axis=1), xp.stack(oi, axis=1)


def _smallest_keyed(d2, idx, k, n, xp):
    """Traced, 64-bit: the ``k`` smallest ``(d2, idx)`` pairs by ``k + 1``
    passes over one integer key per candidate, the bits of ``d2`` (a float
    >= 0: its bits order as it does) with the low ``b`` bits replaced by
    the index (``2^b >= n``). Returns ``(idx (Q, k), exact)``: the key
    orders like ``(d2, idx)`` unless two of a row's ``k + 1`` smallest
    distances agree in all but their low ``b`` bits (relative difference
    below ``2^(b - 52)``); ``exact`` is False when some row has such a
    pair (equal distances included), and the caller then takes the exact
    passes of :func:`_smallest_exact`. The distances of the selected points
    are recomputed by the caller (same arithmetic, same values)."""
    import jax
    b = max(1, int(n - 1).bit_length())
    qn, w = d2.shape
    kk = min(int(k), w)
    passes = min(kk + 1, w)
    bits = jax.lax.bitcast_convert_type(d2, np.int64)
    low = np.int64((1 << b) - 1)
    key = (bits & ~low) | idx.astype(np.int64)
    top = np.int64(np.iinfo(np.int64).max)
    got = []
    for _ in range(passes):
        m = xp.min(key, axis=1)
        got.append(m)
        key = xp.where(key == m[:, None], top, key)
    got = xp.stack(got, axis=1)
    inf_bits = int(np.array(np.inf).view(np.int64)) & ~int(low)
    trunc = got & ~low
    finite = trunc < inf_bits
    exact = ~xp.any(finite[:, 1:] & (trunc[:, 1:] == trunc[:, :-1]))
    sel = xp.where(finite[:, :kk], (got[:, :kk] & low), -1)
    return sel.astype(idx.dtype), exact


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
        ed, ei = _smallest(d2[bad], idx[bad], kk, np)
        sel[bad] = np.where(np.isfinite(ed), ei, -1)
        od[bad] = ed
    return sel, od


def _pad_cols(a, k, fill, xp):
    if a.shape[1] >= k:
        return a[:, :k]
    pad = xp.full((a.shape[0], k - a.shape[1]), fill, dtype=a.dtype)
    return xp.concatenate([a, pad], axis=1)


def candidates(cells, points, queries=None, xp=np):
    """Candidate neighbours of each query point: ``(cand, need)``.

    ``cand`` is (Q, M) int point indices, ``-1`` where empty, ``M =
    capacity``; every point within ``cells.reach`` of a query point is in
    its row when ``need.capacity <= capacity``. ``queries`` defaults to
    ``points``.
    """
    ps, order, query, cap = _prepare(cells, points, queries, xp)
    f = _chunk_fn(cells, ps, order, cap, None, xp)

    def row(*args):
        idx, ok, _, _, cnt = f(*args)
        return xp.where(ok, idx, -1), cnt

    cand, cnt = _rowmap(row, _args(query, None, xp), xp)
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
    drops each point from its own row.
    """
    ps, order, query, cap = _prepare(cells, points, queries, xp,
                                     exclude_self=exclude_self)
    f = _chunk_fn(cells, ps, order, cap, radius, xp)

    def row(*args):
        idx, _, val, d2, cnt = f(*args)
        return idx, val, d2, cnt, xp.sum(val, axis=1)

    idx, val, d2, cnt, nh = _rowmap(row, _args(query, None, xp), xp)
    (ci, cd), _ = _compact(val, [(idx, -1), (d2, np.inf)], cells.hits, xp)
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
    f = _chunk_fn(cells, ps, order, cap, radius, xp, fov=fov)
    k = int(k)

    n = points.shape[0]
    keyed = (xp is not np and np.dtype(points.dtype).itemsize == 8 and k > 0
             and n < 2 ** 31 and not cells.brute)
    pcols = _cols(points)

    def exact(d2, idx):
        od, oi = _smallest(d2, idx, k, xp)
        fin = xp.isfinite(od)
        return xp.where(fin, oi, -1), od

    def row(*args):
        idx, _, val, d2, cnt = f(*args)
        d2 = xp.where(val, d2, xp.inf)
        if xp is np and k > 0 and not cells.brute:
            oi, od = _smallest_np(d2, idx, k, n)
        elif keyed:
            import jax
            sel, ok = _smallest_keyed(d2, idx, k, n, xp)
            got = sel >= 0
            safe = xp.where(got, sel, 0)
            me = args[2:2 + len(pcols)]          # the query coordinates of the chunk
            dd = 0.0
            for a, c in enumerate(pcols):
                da = c[safe] - me[a][:, None]
                if cells.box is not None:
                    da = da - cells.box[a] * xp.round(da / cells.box[a])
                dd = dd + da * da
            fast = (sel, xp.where(got, dd, xp.inf))
            oi, od = jax.lax.cond(ok, lambda: fast, lambda: exact(d2, idx))
        else:
            oi, od = exact(d2, idx)
        fin = oi >= 0
        od = xp.where(fin, xp.sqrt(xp.where(fin, od, 1.0)), xp.inf)
        return _pad_cols(oi, k, -1, xp), _pad_cols(od, k, np.inf, xp), cnt

    oi, od, cnt = _rowmap(row, _args(query, heading, xp), xp)
    oi, od = _unsort(query.rows, [oi, od], xp)
    # nearest keeps no row of hits, so hits are no limit of it (need 0)
    return oi, od, Need(xp.max(cnt), xp.asarray(radius, dtype=od.dtype), 0, query.span)


def kd_nearest(points, radius, k, *, box=None, exclude_self=True):
    """:func:`nearest` of every point among the points by SciPy's k-d tree
    (NumPy only): the same neighbours in the same order (ties by index).

    The tree returns the ``k + 2`` nearest; a row whose ``k``-th distance
    equals the farthest returned one may have tied points the tree left
    out, and is answered again by the cell list (rare: duplicates, lattices).
    """
    from scipy.spatial import cKDTree
    pts = np.asarray(points, dtype=float)
    n = pts.shape[0]
    k = int(k)
    if n == 0 or k == 0:
        return np.full((n, k), -1, np.int64), np.full((n, k), np.inf)
    if box is not None:
        b = np.asarray(box, dtype=float)
        pts = pts - b * np.floor(pts / b)
        pts = np.where(pts >= b, 0.0, pts)
        tree = cKDTree(pts, boxsize=b)
    else:
        tree = cKDTree(pts)
    kq = min(k + 2, n)
    d, j = tree.query(pts, k=kq, distance_upper_bound=np.nextafter(float(radius), np.inf))
    d, j = d.reshape(n, kq), j.reshape(n, kq)
    out = j >= n                       # fewer than kq points in range
    full = ~np.any(out, axis=1) & (kq < n)
    dmax = np.where(out, -np.inf, d).max(axis=1)
    d = np.where(out, np.inf, d)
    j = np.where(out, n, j)
    if exclude_self:                   # drop self: shift the row left over it
        me = j == np.arange(n)[:, None]
        at = np.where(me.any(axis=1), np.argmax(me, axis=1), kq)
        cols = np.arange(kq)[None, :]
        src = np.minimum(cols + (cols >= at[:, None]), kq - 1)
        d = np.take_along_axis(d, src, 1)
        j = np.take_along_axis(j, src, 1)
        last = at < kq
        d[last, -1] = np.inf
        j[last, -1] = n
    # the tree sorts by distance; rows with equal finite distances are
    # put in index order among them
    tied = np.nonzero(np.any((d[:, 1:] == d[:, :-1]) & np.isfinite(d[:, 1:]),
                             axis=1))[0]
    if tied.size:
        o = np.lexsort((j[tied], d[tied]), axis=-1)
        d[tied] = np.take_along_axis(d[tied], o, 1)
        j[tied] = np.take_along_axis(j[tied], o, 1)
    kk = min(k, kq)
    dk = d[:, kk - 1]
    amb = np.nonzero(full & np.isfinite(dk) & (dk == dmax))[0]
    d, j = d[:, :kk], j[:, :kk]
    j = np.where(np.isfinite(d), j, -1)
    if kk < k:
        j = np.pad(j, ((0, 0), (0, k - kk)), constant_values=-1)
        d = np.pad(d, ((0, 0), (0, k - kk)), constant_values=np.inf)
    if amb.size:
        cells = CellList(float(radius), box=box, dim=pts.shape[1])
        ai, ad, _ = nearest(cells, pts, radius, k, pts[amb], np,
                            ids=amb if exclude_self else None)
        j[amb], d[amb] = ai, ad
    return j.astype(np.int64), d


class NeighborSearch:
    """The neighbour search a block owns: a reach, an optional static plan,
    and overflow reporting.

    A block creates one in its constructor (``self.search =
    NeighborSearch(reach=..., points="pose")``; ``points`` names the input
    whose first 2 or 3 columns are the positions) and calls :meth:`nearest`,
    :meth:`within` or :meth:`candidates` from its pure functions.

    - NumPy: no plan is needed; each call sizes itself (exact, any count),
      and a radius above ``reach`` re-plans on the fly. :meth:`nearest` of
      the points among themselves without a field of view uses the k-d
      tree (:func:`kd_nearest`), the rest the cell list.
    - Traced (JAX): the static :class:`CellList` in ``self.cells`` is used.
      It is planned before tracing from the block's initial inputs by the
      compiled engine (:meth:`plan`), or fixed by the user (``capacity=``).
      What each call needed is handed to
      :func:`avblocks.core.diagnostics.report`, so an overflow is caught
      after the run, never silent.

    Parameters: ``reach`` (largest radius), ``points`` (input name),
    ``capacity`` (fix the candidates per point; ``hits`` defaults to it),
    ``box`` (periodic), ``dim`` (2 or 3), ``headroom`` (planned size = need
    at ``t0`` times this, also when re-planning after an overflow),
    ``hits`` (width of :meth:`within` rows), ``table`` (unused).
    See the module docstring for the contract with the compiled engine.
    """

    #: marks a search for :func:`avblocks.core.diagnostics.searches_of`
    neighbor_search = True

    def __init__(self, reach, *, points="pose", capacity=None, box=None, dim=2,
                 headroom=2.0, table=None, hits=None):
        self.reach = float(reach)
        self.points = points
        self.box = box
        self.dim = int(dim)
        self.headroom = float(headroom)
        self.table = table
        self.capacity = None if capacity is None else int(capacity)
        if hits is None and self.capacity is not None:
            hits = self.capacity            # never more hits than candidates
        self.hits = None if hits is None else int(hits)
        self.cells = None
        CellList(self.reach, self.capacity, table, box, self.dim, self.hits)  # validates
        if self.capacity is not None:
            self.cells = CellList(self.reach, self.capacity, table, box, self.dim,
                                  self.hits)

    @property
    def fixed(self) -> bool:
        """True when the user fixed the capacity (the engine never re-plans it)."""
        return self.capacity is not None

    def plan(self, points):
        """Fix the static plan from concrete sample positions (NumPy)."""
        pts = np.asarray(points, dtype=float)[:, : self.dim]
        self.cells = plan_cells(pts, self.reach, capacity=self.capacity,
                                headroom=self.headroom, box=self.box, table=self.table,
                                hits=self.hits)
        return self.cells

    def _cells(self, xp, radius, npoints=None):
        if xp is np:
            r = float(np.max(radius)) if radius is not None else self.reach
            reach = self.reach if r <= self.reach else r
            return CellList(reach, None, self.table, self.box, self.dim)
        if self.cells is None:
            if not math.isfinite(self.reach) and npoints is not None:
                # all pairs: the plan follows from the (static) point count
                return CellList(self.reach, 1, self.table, self.box, self.dim,
                                max(1, int(npoints)))
            raise ParameterError(
                "this neighbour search has no static plan: the compiled engine plans "
                "it from the initial positions, or give capacity=", param="capacity")
        return self.cells

    def _report(self, need, cells, xp):
        if xp is not np:
            from ..core import diagnostics
            diagnostics.report(self, need, cells)

    def candidates(self, points, queries=None, xp=np):
        cells = self._cells(xp, None, points.shape[0])
        cand, need = candidates(cells, points[:, : self.dim],
                                None if queries is None else queries[:, : self.dim], xp)
        self._report(need, cells, xp)
        return cand

    def within(self, points, radius, queries=None, xp=np, **kw):
        cells = self._cells(xp, radius if xp is np else None, points.shape[0])
        idx, dist, need = within(cells, points[:, : self.dim], radius,
                                 None if queries is None else queries[:, : self.dim],
                                 xp, **kw)
        self._report(need, cells, xp)
        return idx, dist

    def nearest(self, points, radius, k, queries=None, xp=np, **kw):
        if (xp is np and queries is None and kw.get("fov") is None
                and kw.get("exclude_self", True) and kw.get("ids") is None
                and np.ndim(radius) == 0):
            # NumPy engine: the k-d tree wins at every N measured
            # (benchmarks/neighbors.py); same neighbours, same order
            return kd_nearest(np.asarray(points)[:, : self.dim], float(radius), k,
                              box=self.box)
        cells = self._cells(xp, radius if xp is np else None, points.shape[0])
        idx, dist, need = nearest(cells, points[:, : self.dim], radius, k,
                                  None if queries is None else queries[:, : self.dim],
                                  xp, **kw)
        self._report(need, cells, xp)
        return idx, dist
