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

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..core.errors import ParameterError

# large odd multipliers of a spatial hash (Teschner et al. 2003 style)
_PRIMES = (73856093, 19349663, 83492791)


class Need(NamedTuple):
    """What a search needed: compare with the :class:`CellList`'s plan.

    ``capacity``: points in the fullest bucket (an int array scalar);
    ``reach``: the largest radius asked for (a float array scalar).
    """

    capacity: object
    reach: object


@dataclass(frozen=True)
class CellList:
    """The static plan of a cell-list search (structural: fixes shapes).

    Parameters
    ----------
    reach : float
        Cell edge lower bound: the largest radius a search may ask for.
        ``inf`` means "no range limit": searches compare every pair
        (O(N^2) work, chunk-free; use only for small N).
    capacity : int or None
        Most points per bucket. ``None``: as many as found (NumPy only).
    table : int or None
        Number of hash buckets (``None``: chosen from N at search time).
    box : tuple of float or None
        Periodic box edge lengths (origin at 0), or ``None`` (free space).
    dim : int
        2 or 3.
    """

    reach: float
    capacity: int | None = None
    table: int | None = None
    box: tuple | None = None
    dim: int = 2

    def __post_init__(self):
        r = float(self.reach)
        if not r > 0:
            raise ParameterError("reach must be > 0", param="reach", expected="> 0",
                                 found=self.reach)
        if self.dim not in (2, 3):
            raise ParameterError("dim must be 2 or 3", param="dim", found=self.dim)
        if self.capacity is not None and int(self.capacity) < 1:
            raise ParameterError("capacity must be >= 1", param="capacity",
                                 found=self.capacity)
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
        return tuple(max(1, int(b // self.reach)) for b in self.box)

    def cell_edges(self):
        """Edge length of a cell along each axis."""
        if self.box is None:
            return (self.reach,) * self.dim
        return tuple(b / c for b, c in zip(self.box, self.cells_per_axis()))

    def offsets(self):
        """(3^D or fewer, D) integer offsets of the cells searched around a cell."""
        per_axis = []
        ncell = self.cells_per_axis()
        for a in range(self.dim):
            if ncell is None or ncell[a] >= 3:
                per_axis.append((-1, 0, 1))
            else:                           # fewer than 3 cells: no cell twice
                per_axis.append(tuple(range(ncell[a])))
        grid = np.stack(np.meshgrid(*per_axis, indexing="ij"), axis=-1)
        return grid.reshape(-1, self.dim)

    def table_size(self, n):
        if self.table is not None:
            return int(self.table)
        return table_size(n)

    def exceeded(self, need) -> str | None:
        """A sentence saying what ``need`` exceeds in this plan, or None."""
        cap = int(np.max(np.asarray(need.capacity)))
        reach = float(np.max(np.asarray(need.reach)))
        msgs = []
        if self.capacity is not None and cap > self.capacity:
            msgs.append(f"a cell held {cap} points, capacity is {self.capacity}")
        if reach > self.reach * (1 + 1e-12):
            msgs.append(f"a search asked for radius {reach:g}, the cells were planned "
                        f"for {self.reach:g}")
        return "; ".join(msgs) or None


def table_size(n) -> int:
    """Default number of hash buckets for ``n`` points: a power of two >= 2 n."""
    return 1 << max(4, int(2 * max(int(n), 1) - 1).bit_length())


def plan_cells(points, reach, *, capacity=None, headroom=2.0, box=None, table=None,
               min_capacity=4) -> CellList:
    """Plan a :class:`CellList` from sample positions (build time, NumPy).

    ``capacity`` defaults to ``max(min_capacity, ceil(headroom * fullest))``
    where ``fullest`` is the fullest bucket for ``points``.
    """
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] not in (2, 3):
        raise ParameterError("points must be (N, 2) or (N, 3)", param="points",
                             found=pts.shape)
    base = CellList(reach, None, table, box, pts.shape[1])
    if capacity is None:
        if base.brute:
            cap = 1
        else:
            need = cell_index(base, pts, np)[3]
            cap = max(int(min_capacity), int(math.ceil(float(headroom) * int(need))))
    else:
        cap = int(capacity)
    return CellList(base.reach, cap, table, base.box, base.dim)


# ---------------------------------------------------------------- internals
def _cell_coords(cells, pos, xp):
    """Integer cell coordinates (N, D) of positions (wrapped into a periodic box)."""
    edges = xp.asarray(cells.cell_edges(), dtype=pos.dtype)
    if cells.box is not None:
        box = xp.asarray(cells.box, dtype=pos.dtype)
        pos = pos - box * xp.floor(pos / box)
        c = xp.floor(pos / edges).astype(np.int32)
        ncell = xp.asarray(cells.cells_per_axis(), dtype=np.int32)
        return xp.clip(c, 0, ncell - 1)      # a point exactly at L rounds up
    return xp.floor(pos / edges).astype(np.int32)


def _hash(c, t, xp):
    """Bucket of integer cell coordinates (N, D) in a table of ``t`` (power of 2)."""
    h = c[..., 0].astype(np.uint32) * np.uint32(_PRIMES[0])
    for a in range(1, c.shape[-1]):
        h = h ^ (c[..., a].astype(np.uint32) * np.uint32(_PRIMES[a]))
    return (h & np.uint32(t - 1)).astype(np.int32)


def cell_index(cells, points, xp=np):
    """Sort ``points`` into buckets.

    Returns ``(order, start, count, fullest, coords)``: point indices sorted
    by bucket (stable), each bucket's first slot in ``order`` and its count
    (T,), the fullest bucket's count, and each point's cell coordinates.
    """
    n = points.shape[0]
    t = cells.table_size(n)
    c = _cell_coords(cells, points, xp)
    b = _hash(c, t, xp)
    order = xp.argsort(b, stable=True) if xp is not np else np.argsort(b, kind="stable")
    count = xp.bincount(b, length=t) if xp is not np else np.bincount(b, minlength=t)
    start = xp.cumsum(count) - count
    return order, start, count, xp.max(count), c


def candidates(cells, points, queries=None, xp=np, *, index=None):
    """Candidate neighbours of each query point: ``(cand, need)``.

    ``cand`` is (Q, M) int32 point indices, ``-1`` where empty, ``M = (cells
    searched) * capacity``; every point within ``cells.reach`` of a query
    point is in its row when ``need.capacity <= capacity``. ``queries``
    defaults to ``points``. ``index`` is a precomputed :func:`cell_index`.
    """
    if cells.brute:
        n = points.shape[0]
        q = points.shape[0] if queries is None else queries.shape[0]
        cand = xp.broadcast_to(xp.arange(n, dtype=np.int32)[None, :], (q, n))
        return cand, Need(xp.asarray(0), xp.asarray(0.0))
    order, start, count, fullest, pc = index if index is not None else \
        cell_index(cells, points, xp)
    cap = cells.capacity
    if cap is None:
        if xp is not np:
            raise ParameterError("a traced search needs a static capacity",
                                 param="capacity", hint="plan it with plan_cells()")
        cap = max(int(fullest), 1)
    qc = pc if queries is None else _cell_coords(cells, queries, xp)
    t = cells.table_size(points.shape[0])
    offs = cells.offsets()
    ncell = cells.cells_per_axis()
    cols = []
    slot = xp.arange(cap, dtype=np.int32)
    for o in offs:
        want = qc + xp.asarray(o, dtype=np.int32)
        if ncell is not None:
            want = xp.mod(want, xp.asarray(ncell, dtype=np.int32))
        b = _hash(want, t, xp)                               # (Q,)
        s, k = start[b], count[b]
        pos = s[:, None] + slot[None, :]                     # (Q, cap)
        ok = slot[None, :] < k[:, None]
        j = order[xp.where(ok, pos, 0)]
        same = xp.all(pc[j] == want[:, None, :], axis=-1)    # true cell, not a bucket mate
        cols.append(xp.where(ok & same, j, -1).astype(np.int32))
    cand = xp.concatenate(cols, axis=1)
    return cand, Need(fullest, xp.asarray(0.0))


def displacement(cells, points, cand, queries=None, xp=np):
    """``p_cand - q`` (Q, M, D) by the minimum image in a periodic box."""
    q = points if queries is None else queries
    d = points[xp.maximum(cand, 0)] - q[:, None, :]
    if cells.box is not None:
        box = xp.asarray(cells.box, dtype=d.dtype)
        d = d - box * xp.round(d / box)
    return d


def within(cells, points, radius, queries=None, xp=np, *, exclude_self=True,
           index=None):
    """Every point within ``radius`` (inclusive) of each query point.

    Returns ``(idx, dist, need)``: (Q, M) int32 indices (``-1`` where none;
    unsorted) and their distances (``inf`` where none). With ``queries``
    None the query points are the points and ``exclude_self`` drops each
    point from its own row.
    """
    cand, need = candidates(cells, points, queries, xp, index=index)
    d = displacement(cells, points, cand, queries, xp)
    d2 = xp.sum(d * d, axis=-1)
    r = xp.asarray(radius, dtype=d2.dtype)
    ok = (cand >= 0) & (d2 <= r * r)
    if exclude_self and queries is None:
        ok = ok & (cand != xp.arange(points.shape[0], dtype=np.int32)[:, None])
    idx = xp.where(ok, cand, -1)
    dist = xp.where(ok, xp.sqrt(xp.where(ok, d2, 0.0)), xp.inf)
    return idx, dist, Need(need.capacity, r)


def nearest(cells, points, radius, k, queries=None, xp=np, *, heading=None,
            fov=None, exclude_self=True, index=None):
    """The ``k`` nearest points within ``radius`` of each query point.

    Sorted by distance, ties by index. With ``heading`` (Q,) and ``fov``
    (full angle), only points whose bearing from the query point relative
    to its heading lies in ``[-fov/2, fov/2]`` count.

    Returns ``(idx, dist, need)``: (Q, k) int32 (``-1`` padded) and float
    (``inf`` padded).
    """
    idx, dist, need = within(cells, points, radius, queries, xp,
                             exclude_self=exclude_self, index=index)
    if fov is not None:
        d = displacement(cells, points, idx, queries, xp)
        rel = xp.arctan2(d[..., 1], d[..., 0]) - heading[:, None]
        rel = xp.abs(xp.mod(rel + np.pi, 2 * np.pi) - np.pi)
        ok = (idx >= 0) & (rel <= 0.5 * fov + 1e-12)
        idx = xp.where(ok, idx, -1)
        dist = xp.where(ok, dist, xp.inf)
    big = np.iinfo(np.int32).max
    key_i = xp.where(idx >= 0, idx, big)
    m = idx.shape[1]
    if xp is np:
        order = np.lexsort((key_i, dist), axis=-1)[:, :k]
    else:
        import jax
        cols = xp.broadcast_to(xp.arange(m, dtype=np.int32), idx.shape)
        order = jax.lax.sort((dist, key_i, cols), dimension=1, num_keys=2)[2][:, :k]
    idx = xp.take_along_axis(idx, order, axis=1)
    dist = xp.take_along_axis(dist, order, axis=1)
    if m < k:
        pad = k - m
        idx = xp.concatenate([idx, xp.full((idx.shape[0], pad), -1, dtype=idx.dtype)], 1)
        dist = xp.concatenate([dist, xp.full((dist.shape[0], pad), xp.inf,
                                             dtype=dist.dtype)], 1)
    return idx, dist, need


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
                 headroom=2.0, table=None):
        self.reach = float(reach)
        self.points = points
        self.box = box
        self.dim = int(dim)
        self.headroom = float(headroom)
        self.table = table
        self.capacity = None if capacity is None else int(capacity)
        self.cells = None
        CellList(self.reach, self.capacity, table, box, self.dim)   # validates
        if self.capacity is not None or not math.isfinite(self.reach):
            self.cells = CellList(self.reach, self.capacity or 1, table, box, self.dim)

    def plan(self, points):
        """Fix the static plan from concrete sample positions (NumPy)."""
        pts = np.asarray(points, dtype=float)[:, : self.dim]
        self.cells = plan_cells(pts, self.reach, capacity=self.capacity,
                                headroom=self.headroom, box=self.box, table=self.table)
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
