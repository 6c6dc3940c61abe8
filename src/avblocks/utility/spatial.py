r"""Neighbour search that traces: a hashed cell list with static shapes.

One implementation, written with the array namespace ``xp`` a block is
handed, serves the NumPy engine and the compiled (JAX) engine alike, under
``jit``, ``vmap`` and ``grad``.

Method
------
Space is cut into cubic cells of edge ``>= reach`` (the largest radius that
will be queried). Each point's integer cell coordinates are hashed into a
table of ``T`` buckets (static size); the points are sorted by bucket
(stable, so ties keep index order), bucket counts come from a ``bincount``
and their starts from a cumulative sum. A query point looks at the
``3^D`` cells around its own (fewer when a periodic box has fewer than 3
cells along an axis) and takes up to ``capacity`` points from each of their
buckets, keeping only the points whose true cell is the one asked for (two
cells may share a bucket). Every point within ``reach`` of the query point
is among these ``M = 3^D * capacity`` candidates, so a search is exact
whenever no bucket holds more than ``capacity`` points.

Cost per call: a sort of N bucket numbers, a bincount, and ``Q * M``
distances; O(N log N) with a small log, O(N) memory at constant density.
No (N, N) array is ever formed.

Static shapes and overflow
--------------------------
``capacity`` (points per bucket), ``reach`` and the table size are fixed
when a :class:`CellList` is planned (:func:`plan_cells`, from the first
positions with headroom, or given by the user). Every search also returns
what it *needed* (:class:`Need`: the fullest bucket and the largest radius
asked for), so a caller can tell, never silently, when the plan was too
small. Under NumPy, ``capacity=None`` plans nothing: each call uses the
count it finds (shapes may change from call to call).

Periodic boxes
--------------
With ``box=(L_x, L_y[, L_z])`` positions are taken modulo the box (origin at
0) and displacements by the minimum image, ``d - L round(d / L)``; ``reach``
must not exceed half the smallest box edge.

Ordering
--------
:func:`nearest` returns neighbours sorted by distance, ties broken by the
smaller index, the same order as a brute-force ``lexsort((index,
distance))`` (tests compare against SciPy's k-d tree on clouds with
duplicates, points exactly at the radius and on cell borders).
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
    point had within the radius (0 when not counted).
    """

    capacity: object
    reach: object
    hits: object = 0


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
        if reach > self.reach * (1 + 1e-12):
            msgs.append(f"a search asked for radius {reach:g}, the cells were planned "
                        f"for {self.reach:g}")
        return "; ".join(msgs) or None

    def grown(self, need, headroom=1.5) -> "CellList":
        """This plan with room for ``need`` (times ``headroom``)."""
        cap = int(np.max(np.asarray(need.capacity)))
        hits = int(np.max(np.asarray(need.hits)))
        new_cap = self.capacity
        if self.capacity is not None and cap > self.capacity:
            new_cap = int(math.ceil(headroom * cap))
        new_hits = self.hits
        if self.hits is not None and hits > self.hits:
            new_hits = int(math.ceil(headroom * hits))
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


def _sort(keys, xp):
    if xp is np:
        return np.argsort(keys, kind="stable")
    return xp.argsort(keys, stable=True)


class _Layout(NamedTuple):
    """Points sorted by cell (see :func:`layout`)."""

    order: object      # (N,) point indices sorted by cell key (stable)
    skey: object       # (N,) sorted cell keys
    coords: object     # (N, D) cell coordinates of the points (grid frame)
    shift: object      # (D,) grid frame origin in cells (free space) or None
    dims: object       # (D,) cells per axis of the grid frame
    strides: tuple     # key strides per axis (array scalars)


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
    order = _sort(key, xp)
    return _Layout(order, key[order], c, shift, dims, tuple(strides))


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
        g = int(np.prod(np.asarray(lay.dims)))
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


class _Hits(NamedTuple):
    """Candidates of every query, in the order the queries were processed."""

    pos: object      # (Q, M) slots into the sorted points (or point indices)
    ok: object       # (Q, M) slot holds a candidate
    idx: object      # (Q, M) point index of each slot
    d: object        # (Q, M, D) displacement candidate - query (minimum image)
    rows: object     # (Q,) the query each processed row is, or None (identity)
    need: object     # largest candidate count


def _search(cells, points, queries, xp, *, sort_queries=True):
    """Candidates of each query point (rows sorted by cell when the queries
    are the points, for locality; ``rows`` maps them back)."""
    n = points.shape[0]
    if cells.brute:
        q = points if queries is None else queries
        qn = q.shape[0]
        it = _int_type(points, xp)
        pos = xp.broadcast_to(xp.arange(n, dtype=it)[None, :], (qn, n))
        d = points[None, :, :] - q[:, None, :]
        if cells.box is not None:
            box = xp.asarray(cells.box, dtype=d.dtype)
            d = d - box * xp.round(d / box)
        return _Hits(pos, xp.ones((qn, n), dtype=bool), pos, d, None, xp.asarray(n))
    lay = layout(cells, points, xp)
    ps = points[lay.order]
    if queries is None and sort_queries:
        q, qc, rows = ps, lay.coords[lay.order], lay.order
    elif queries is None:
        q, qc, rows = points, lay.coords, None
    else:
        q, qc, rows = queries, _query_cells(cells, lay, queries, xp), None
    bounds = _bounds(cells, lay, _windows(cells, lay, qc, xp), xp)
    cap = cells.capacity
    if cap is None:
        if xp is not np:
            raise ParameterError("a traced search needs a static capacity",
                                 param="capacity", hint="plan it with plan_cells()")
        cap = max(1, int(np.max(sum(b - a for a, b in bounds)))) if n else 1
    pos, ok, need = _gather_slots(bounds, cap, xp)
    d = ps[pos] - q[:, None, :]
    if cells.box is not None:
        box = xp.asarray(cells.box, dtype=d.dtype)
        d = d - box * xp.round(d / box)
    return _Hits(pos, ok, lay.order[pos], d, rows, need)


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
    return [a[inv] for a in arrays]


def _filter(cells, hits, radius, xp, *, exclude_self, heading=None, fov=None):
    """(valid mask, squared distances) of the candidates."""
    d2 = xp.sum(hits.d * hits.d, axis=-1)
    r = xp.asarray(radius, dtype=d2.dtype)
    ok = hits.ok & (d2 <= r * r)
    if exclude_self:
        qn = hits.idx.shape[0]
        if hits.rows is None:
            me = xp.arange(qn, dtype=hits.idx.dtype)
        else:
            me = hits.rows.astype(hits.idx.dtype)
        ok = ok & (hits.idx != me[:, None])
    if fov is not None:
        h = heading if hits.rows is None else heading[hits.rows]
        rel = xp.arctan2(hits.d[..., 1], hits.d[..., 0]) - h[:, None]
        rel = xp.abs(xp.mod(rel + np.pi, 2 * np.pi) - np.pi)
        ok = ok & (rel <= 0.5 * fov + 1e-12)
    return ok, d2


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
    hits = _search(cells, points, queries, xp)
    cand = xp.where(hits.ok, hits.idx, -1)
    (cand,) = _unsort(hits.rows, [cand], xp)
    return cand, Need(hits.need, xp.asarray(0.0))


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
    hits = _search(cells, points, queries, xp)
    ok, d2 = _filter(cells, hits, radius, xp, exclude_self=exclude_self and queries is None)
    (ci, cd), hneed = _compact(ok, [(hits.idx, -1), (d2, np.inf)], cells.hits, xp)
    dist = xp.sqrt(cd)
    ci, dist = _unsort(hits.rows, [ci, dist], xp)
    return ci, dist, Need(hits.need, xp.asarray(radius, dtype=dist.dtype), hneed)


def nearest(cells, points, radius, k, queries=None, xp=np, *, heading=None,
            fov=None, exclude_self=True):
    """The ``k`` nearest points within ``radius`` of each query point.

    Sorted by distance, ties by index. With ``heading`` (Q,) and ``fov``
    (full angle), only points whose bearing from the query point relative
    to its heading lies in ``[-fov/2, fov/2]`` count.

    Returns ``(idx, dist, need)``: (Q, k) int (``-1`` padded) and float
    (``inf`` padded).
    """
    hits = _search(cells, points, queries, xp)
    ok, d2 = _filter(cells, hits, radius, xp, exclude_self=exclude_self and queries is None,
                     heading=heading, fov=fov)
    hneed = xp.max(xp.sum(ok, axis=1)) if ok.shape[1] else xp.asarray(0)
    od, oi = _smallest(xp.where(ok, d2, xp.inf), hits.idx, int(k), xp)
    fin = xp.isfinite(od)
    oi = xp.where(fin, oi, -1)
    od = _pad_cols(xp.sqrt(xp.where(fin, od, 0.0)) + xp.where(fin, 0.0, xp.inf), int(k),
                   np.inf, xp)
    oi = _pad_cols(oi, int(k), -1, xp)
    oi, od = _unsort(hits.rows, [oi, od], xp)
    return oi, od, Need(hits.need, xp.asarray(radius, dtype=od.dtype), hneed)


class NeighborSearch:
    """The neighbour search a block owns: a reach, an optional static plan,
    and overflow reporting.

    A block creates one in its constructor (``self.search =
    NeighborSearch(reach=..., points="pose")``; ``points`` names the input
    whose first 2 or 3 columns are the positions) and calls :meth:`nearest`,
    :meth:`within` or :meth:`candidates` from its pure functions.

    - NumPy: no plan is needed; each call sizes itself (exact, any count),
      and a radius above ``reach`` re-plans on the fly.
    - Traced (JAX): the static :class:`CellList` in ``self.cells`` is used.
      It is planned before tracing from the block's initial inputs by the
      compiled engine (:meth:`plan`), or fixed by the user (``capacity=``).
      What each call needed is handed to
      :func:`avblocks.core.diagnostics.report`, so an overflow is caught
      after the run, never silent.
    """

    def __init__(self, reach, *, points="pose", capacity=None, box=None, dim=2,
                 headroom=1.5, table=None, hits=None):
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

    def _cells(self, xp, radius):
        if xp is np:
            r = float(np.max(radius)) if radius is not None else self.reach
            reach = self.reach if r <= self.reach else r
            return CellList(reach, None, self.table, self.box, self.dim)
        if self.cells is None:
            raise ParameterError(
                "this neighbour search has no static plan: the compiled engine plans "
                "it from the initial positions, or give capacity=", param="capacity")
        return self.cells

    def _report(self, need, cells, xp):
        if xp is not np:
            from ..core import diagnostics
            diagnostics.report(self, need, cells)

    def candidates(self, points, queries=None, xp=np):
        cells = self._cells(xp, None)
        cand, need = candidates(cells, points[:, : self.dim],
                                None if queries is None else queries[:, : self.dim], xp)
        self._report(need, cells, xp)
        return cand

    def within(self, points, radius, queries=None, xp=np, **kw):
        cells = self._cells(xp, radius if xp is np else None)
        idx, dist, need = within(cells, points[:, : self.dim], radius,
                                 None if queries is None else queries[:, : self.dim],
                                 xp, **kw)
        self._report(need, cells, xp)
        return idx, dist

    def nearest(self, points, radius, k, queries=None, xp=np, **kw):
        cells = self._cells(xp, radius if xp is np else None)
        idx, dist, need = nearest(cells, points[:, : self.dim], radius, k,
                                  None if queries is None else queries[:, : self.dim],
                                  xp, **kw)
        self._report(need, cells, xp)
        return idx, dist
