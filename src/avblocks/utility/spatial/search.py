"""The neighbour search a block owns (:class:`NeighborSearch`)."""

from __future__ import annotations

import math

import numpy as np

from ...core.errors import ParameterError
from .cells import CellList
from .kdtree import kd_nearest, kd_within
from .queries import candidates, nearest, plan_cells, within


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
      tree (:func:`kd_nearest`), and so does :meth:`within` in free space
      (:func:`kd_within`); the rest the cell list. Both give the cell
      list's results exactly.
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

    ``counts_hits`` (attribute, default True): whether a plan counts the
    most points within ``reach`` of one point (the plan's ``hits``, which
    only :meth:`within` rows and the plans' users such as a Verlet list
    read). A block whose search only ever answers :meth:`nearest` or
    :meth:`candidates` sets it False: its plans then leave ``hits`` out
    (None), and planning skips the count (at 10^6 points most of a plan's
    time: a k-d tree query of every point).
    """

    #: marks a search for :func:`avblocks.core.diagnostics.searches_of`
    neighbor_search = True
    #: the class of its static plan (the compiled engine's plan book makes
    #: plans through it: core does not import this package)
    plan_type = CellList

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
        self.counts_hits = True
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
                                hits=self.hits, count_hits=self.counts_hits)
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
            from ...core import diagnostics
            diagnostics.report(self, need, cells)

    def candidates(self, points, queries=None, xp=np):
        cells = self._cells(xp, None, points.shape[0])
        cand, need = candidates(cells, points[:, : self.dim],
                                None if queries is None else queries[:, : self.dim], xp)
        self._report(need, cells, xp)
        return cand

    def within(self, points, radius, queries=None, xp=np, **kw):
        if (xp is np and self.box is None and np.ndim(radius) == 0
                and set(kw) <= {"exclude_self"}):
            # NumPy engine: the k-d tree proposes the pairs (faster than the
            # cell list from a few hundred points on, benchmarks/neighbors.py);
            # the rows are the cell list's, entry for entry
            r = float(radius)
            return kd_within(np.asarray(points)[:, : self.dim], r,
                             None if queries is None else
                             np.asarray(queries)[:, : self.dim],
                             reach=max(self.reach, r), **kw)
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
