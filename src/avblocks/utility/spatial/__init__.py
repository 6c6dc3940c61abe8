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
field of view, and takes the ``k`` smallest ``(distance, index)`` pairs,
exact, ties broken by the smaller index: the order of a brute-force
``lexsort((index, distance))``. Traced, each candidate gets one 64-bit key
(the bits of its squared distance, the low bits replaced by its slot in
the sorted points) and a tournament takes the ``k + 1`` smallest keys: the
row is cut into groups of about ``sqrt(W)`` (8 to 32), each group keeps
its minimum, and each pick reads the group minima and then one group,
``O(W + k (W / g + g))`` for ``W`` candidates in groups of ``g`` instead of
``O(k W)`` for ``k`` passes over the row
(measured at N = 10^4 in a contracted flock, 405 candidates per row: 160
ms per search with passes, 50 ms with the tournament). Only the selected
slots become point indices. Where two of a row's ``k + 1`` smallest
distances agree in all but the slot bits (equal distances), the chunk
takes exact passes over ``(distance, index)`` instead. NumPy:
``argpartition`` of such keys (the point index in the low bits). Query rows are handled in chunks of
:data:`CHUNK` (NumPy) or ``TRACED_CHUNK`` (1024, ``lax.map``), rows in
cell order for locality, so the temporaries stay ``O(chunk *
capacity)``. Cost per call: a sort of N keys, ``2 * 5^(D-1)`` binary
searches per query, ``O(capacity)`` per query for the distances and keys
and ``O(k (capacity / 16 + 16))`` for the selection. No (N, N) array is
ever formed (except with ``reach = inf``: every pair).

Under NumPy, :class:`NeighborSearch` answers radius queries with SciPy's
k-d tree (:func:`kd_nearest`: faster at every N measured here, see
``benchmarks/neighbors.py``), made exact on ties: a row whose ``k``-th
distance equals the farthest the tree returned is answered again by the
cell list. Both give the same neighbours in the same order. Radius
queries (:meth:`NeighborSearch.within`) in free space take the tree's
pairs too (:func:`kd_within`), arranged as the cell list's rows.

Verlet lists (:mod:`.verlet`): a list of the points within ``radius +
skin`` of each point, kept by its owner (``environment.Neighbors(skin=)``
holds it as discrete state) and rebuilt only when the points may have moved
``skin / 2`` relative to each other; each query then selects among a few
candidates. Same results as a fresh search.

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

from .cells import CellList, Need
from .kdtree import kd_nearest, kd_within
from .layout import _sort, layout  # noqa: F401 (_sort: tests of the traced sort)
from .queries import CHUNK, candidates, displacement, nearest, plan_cells, within
from .search import NeighborSearch

__all__ = ["Need", "CellList", "plan_cells", "layout", "candidates", "displacement",
           "within", "nearest", "kd_nearest", "kd_within", "NeighborSearch", "CHUNK"]
