"""Helpers shared by the environment blocks (private)."""

from __future__ import annotations

import math

import numpy as np

from ..core.errors import ParameterError
from ..core.params import positive_scalar
from ..utility.arrays import norm2
from .edges import EdgeGrid

_KINDS = {"pose": (3, "m, m, rad", ("x", "y", "theta"), "agent poses"),
          "position": (2, "m, m", ("x", "y"), "agent positions")}


def declare_agents_input(block, n, kind, *, feedthrough=True, need_heading=False):
    """Declare the agent input: ``pose`` (N, 3) or ``position`` (N, 2)."""
    name = type(block).__name__
    if kind not in _KINDS:
        raise ParameterError("input must be 'pose' or 'position'", block=name,
                             param="input", expected=sorted(_KINDS), found=kind)
    if need_heading and kind != "pose":
        raise ParameterError("this option needs headings: use input='pose'",
                             block=name, param="input", found=kind)
    dim, unit, labels, doc = _KINDS[kind]
    block.declare_input(kind, (n, dim), unit=unit, labels=labels, doc=doc,
                        feedthrough=feedthrough)
    return kind


def agent_count(n, block):
    try:
        n = int(n)
    except (TypeError, ValueError):
        n = -1
    if n < 1:
        raise ParameterError("number of agents must be an integer >= 1", block=block,
                             param="n", expected=">= 1", found=n)
    return n


def maybe_periodic(block, period):
    """Make ``block`` discrete with ``period`` (None: continuous)."""
    if period is not None:
        block.declare_periodic(positive_scalar(period, type(block).__name__, "period"))


def to_numpy(a):
    return np.asarray(a)


class EdgeGridOwner:
    """What a block that queries obstacles as an edge grid shares
    (``Collision``, ``RangeSensor``): the grids it built per reach (a memo of
    values, not part of the compile key), the grid of its own reach, and the
    static plans a compiled run checks (its agent search and that grid).
    The block sets ``world``, ``method``, ``search``, ``_reach`` and
    ``_grid_cache``."""

    def _grid(self, reach):
        if self.world is None:
            return None
        g = self._grid_cache.get(reach)
        if g is None:
            g = self._grid_cache[reach] = EdgeGrid(self.world, reach)
        return g

    @property
    def edges(self):
        """The world as an :class:`~avblocks.environment.edges.EdgeGrid`
        (built on first use; None without a world)."""
        return self._grid(self._reach)

    def searches(self):
        """The static plans of a compiled run: the agent search and the edge
        grid (see :mod:`avblocks.core.compiled.plans`)."""
        if self.method == "shapely":
            return []
        return [s for s in (self.search, self.edges) if s is not None]


#: Agent counts up to which the agent-agent searches of Collision and
#: RangeSensor compare all pairs by default (an (N, N) product: exact, no
#: capacity to plan) when no capacity is given.
SMALL_N = 64


def all_pairs(search, points, xp):
    """Every agent against every other, ``(idx (N, N), dist (N, N))`` with
    ``idx[i, j] = j`` and ``-1`` on the diagonal (not a candidate; its
    ``dist`` is 1), when ``search`` compares every pair anyway (infinite
    reach, no periodic box: the blocks' default for N <= SMALL_N); ``None``
    for a planned search. The same candidates as ``search.within`` (callers
    reduce over them, so the order does not matter) without the cell
    list's sorting and compaction, which under ``vmap`` cost several times
    the rest of a small diagram's step (the navigation task: 2.5x), and
    without a gather: column ``j`` is agent ``j`` (callers broadcast the
    agents' values along the rows rather than index them with ``idx``)."""
    if search is None or search.box is not None or math.isfinite(search.reach):
        return None
    n = points.shape[0]
    eye = np.eye(n, dtype=bool)
    idx = np.where(eye, -1, np.arange(n)[None, :])
    s = xp.where(eye, 1.0, norm2(points[None, :, :] - points[:, None, :]))
    return idx, xp.sqrt(s)
