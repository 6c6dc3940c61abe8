r"""Obstacles as static edge arrays with a uniform-grid broad phase, and the
``xp`` geometry kernels that work on them (traceable by JAX).

A :class:`World` holds shapely polygons; the compiled engine cannot call
shapely. :class:`EdgeGrid` turns the world once, at build time, into plain
arrays of fixed shape:

- ``seg`` (E + 1, 2, 2): every polygon edge (exterior rings and holes) as
  start/end points; the last row is a padding edge far away, so a gather
  with index ``-1`` lands on it harmlessly. ``owner`` (E + 1,): obstacle
  index of each edge (``-1`` for the padding row).
- circles (exact): ``circle_center`` (Mc + 1, 2), ``circle_radius``,
  ``circle_owner`` (padded the same way).
- a uniform grid of square cells of edge ``h`` over the obstacles' bounding
  box grown by ``reach``. Per cell, padded to the fullest cell:
  ``cell_edges`` (C, K): the edges whose bounding box meets the cell grown
  by ``reach``; ``cell_circles`` (C, Kc) likewise; ``cell_polys`` (C, P):
  the polygons that own one of those edges or contain the cell's reference
  point ``cell_ref`` (C, 2), and ``cell_ref_in`` (C, P): whether the
  reference point is inside each of them.

Queries never form an (N, E) product: a point looks up its cell and works
on that cell's ``K`` candidate edges only, (N, K), with ``K`` fixed when the
grid is built (the bounded candidate product the broad phase allows).
Small worlds are the exception (``dense``: at most
:data:`~avblocks.environment.boxes.DENSE_ITEMS` items): there every point
tests every item, the axis-aligned rectangles (walls included) as boxes in
closed form (``boxes``, ``box_owner``; the other polygons' edges:
``rest``), which costs less than a cell's gathers (see
:mod:`~avblocks.environment.boxes`).

Point in polygon from a cell's reference point
----------------------------------------------
Inside/outside is not local, so each cell carries a reference point ``c``
(its centre, nudged off any edge) whose status is computed once. A query
point ``q`` in the cell has the status of ``c`` flipped once per edge of
the polygon that the segment ``q -> c`` crosses (crossing number along a
path). That segment lies inside the cell, so every edge it can cross is in
the cell's list. Crossings use the half-open rule in the frame of the
path: with ``d = c - q``, ``s_a = d x (a - q)``, ``s_b = d x (b - q)`` an
edge ``a b`` crosses when ``(s_a > 0) != (s_b > 0)`` and the crossing lies
on the path, so a path through a vertex counts it once (shared vertices get
bit-identical ``s``). Points on an edge are at distance 0 (a contact), so
their parity never decides a result.

Kernels (each broadcasts element-wise, ``xp`` arrays)
-----------------------------------------------------
- :func:`point_segment_distance`: the distance to ``a`` or ``b`` past the
  ends (``t = (p - a).(b - a) / |b - a|^2`` outside (0, 1)), else
  ``|(p - a) x (b - a)| / |b - a|``;
- :func:`ray_segment`: ray ``o + t u`` (``|u| = 1``) vs ``a + s e``:
  ``t = ((a - o) x e) / (u x e)``, ``s = ((a - o) x u) / (u x e)``, a hit when
  ``t >= 0`` and ``0 <= s <= 1``;
- :func:`ray_circle`: ``t = f.u - sqrt(r^2 - (|f|^2 - (f.u)^2))``, ``f = c - o``
  (0 when ``o`` is inside);
- :func:`point_in_polygons`: crossing number of a horizontal ray against
  all edges (brute force, (N, E): for tests and small worlds);
- :func:`segment_segment_distance` (and the squared forms
  :func:`point_segment_dist2`, :func:`segment_segment_dist2` used for
  ``<=`` tests), :func:`point_in_ring` (a vertex loop);
- :meth:`EdgeGrid.disc_hits`: circle (disc) vs every obstacle through the
  grid: ``inside(q) or dist(q, boundary) <= r`` for polygons,
  ``|q - c| <= r + R`` for circles;
- :meth:`EdgeGrid.polygon_hits`: posed polygons (a vehicle footprint) vs
  every obstacle, with a margin: ``dist(F, O) <= m`` where the boundary
  distance is the least segment-segment distance over footprint edges x
  candidate edges, and containment either way is tested with one vertex
  (a footprint vertex inside ``O`` through the grid, an obstacle edge's
  start inside ``F`` by crossing number).

Exactness: the grid answers are the same set predicates as shapely's
(``distance(point, polygon) <= r``), computed in float64 from the same
vertices; they agree with shapely except for distances within ~1e-12 of
``r`` (tests state 1e-9).
"""

from __future__ import annotations

import math

import numpy as np

from ..core.errors import ParameterError
from .boxes import DENSE_ITEMS, disc_hits_dense, split_boxes
from .kernels import (  # noqa: F401  (re-exported: the kernels' documented home)
    _cross,
    _norm,
    path_crosses,
    point_in_polygons,
    point_in_ring,
    point_segment_dist2,
    point_segment_distance,
    ray_circle,
    ray_segment,
    segment_segment_dist2,
    segment_segment_distance,
)

#: Padding coordinate: far from anything, finite, and small enough that its
#: square stays finite in float32 (so no inf or NaN reaches a gradient).
_FAR = 1e9


# -------------------------------------------------------------- the arrays
def world_edges(world):
    """``(seg (E, 2, 2), owner (E,))`` of a :class:`World` (circles excluded)."""
    s = np.asarray(world.segments, dtype=float).reshape(-1, 2, 2)
    return s, np.asarray(world.segment_owner, dtype=np.int64)


def _pad_rows(lists, width, fill=-1):
    out = np.full((len(lists), max(width, 1)), fill, dtype=np.int32)
    for i, li in enumerate(lists):
        out[i, :len(li)] = li
    return out


class EdgeGrid:
    """A world's obstacles as padded arrays with a uniform-grid broad phase.

    Parameters
    ----------
    world : World
    reach : float
        Largest query radius (disc radius, or a range sensor's
        ``max_range``): every edge and circle within ``reach`` of a point is
        among the candidates of the point's cell.
    cell : float, optional
        Cell edge (default ``max(reach, extent / 256)``, grown so that the
        grid has at most ``max_cells`` cells).
    max_cells : int
        Cap on the number of cells (default 2^16).

    All arrays are NumPy constants (structural); queries take ``xp``.

    In a compiled run the grid is a fixed plan like a neighbour search's:
    a block lists it in its ``searches()``, a query hands the radius it
    asked for to :func:`avblocks.core.diagnostics.report`, and a radius
    beyond ``reach`` stops the run with an error naming the block (the grid
    is never re-planned: build the block with a larger ``reach=``).
    """

    #: what the compiled engine's overflow check reads (see
    #: :mod:`avblocks.core.compiled.plans`): a plan fixed at construction,
    #: with a reach and no capacity or hit width to grow
    neighbor_search = True
    fixed = True
    capacity = None
    hits = None
    brute = False
    box = None
    headroom = 1.0

    @property
    def cells(self):
        """The plan the overflow check compares with: the grid itself."""
        return self

    def __init__(self, world, reach, *, cell=None, max_cells=1 << 16):
        import shapely
        reach = float(reach)
        if not (math.isfinite(reach) and reach >= 0):
            raise ParameterError("reach must be finite and >= 0", param="reach",
                                 found=reach)
        self.reach = reach
        seg, owner = world_edges(world)
        self.n_obstacles = int(world.n_obstacles)
        self.n_edges = len(seg)
        cid = np.nonzero(world.is_circle)[0]
        cc, cr = world.circle_center[cid], world.circle_radius[cid]
        self.n_circles = len(cid)
        far = np.full((1, 2, 2), _FAR)
        self.seg = np.concatenate([seg, far])
        self.owner = np.concatenate([owner, [-1]]).astype(np.int32)
        self.circle_center = np.concatenate([cc, [[_FAR, _FAR]]])
        self.circle_radius = np.concatenate([cr, [0.0]])
        self.circle_owner = np.concatenate([cid, [-1]]).astype(np.int32)
        # axis-aligned rectangles as boxes; small worlds are queried densely
        self.boxes, self.box_owner, self.rest = split_boxes(seg, owner)
        self.dense = len(self.boxes) + len(self.rest) + self.n_circles <= DENSE_ITEMS
        # bounding boxes of edges and circles
        lo = np.concatenate([seg.min(axis=1), cc - cr[:, None]]) if len(seg) + len(cid) \
            else np.zeros((0, 2))
        hi = np.concatenate([seg.max(axis=1), cc + cr[:, None]]) if len(seg) + len(cid) \
            else np.zeros((0, 2))
        if len(lo) == 0:
            lo0, hi0 = np.zeros(2), np.ones(2)
        else:
            lo0, hi0 = lo.min(axis=0), hi.max(axis=0)
        ext = float(np.max(hi0 - lo0))
        h = float(cell) if cell is not None else max(reach, ext / 256.0, 1e-9)
        span = hi0 - lo0 + 2 * reach
        while np.prod(np.ceil(span / h) + 2) > max_cells:
            h *= 1.25
        self.cell = h
        self.origin = lo0 - reach - h
        self.shape = tuple(int(v) for v in np.ceil(span / h) + 2)      # (nx, ny)
        nx, ny = self.shape
        C = nx * ny
        # cells touched by each item's box grown by reach
        e_lists = [[] for _ in range(C)]
        c_lists = [[] for _ in range(C)]
        for k in range(len(lo)):
            i0, j0 = np.floor((lo[k] - reach - self.origin) / h).astype(int)
            i1, j1 = np.floor((hi[k] + reach - self.origin) / h).astype(int)
            i0, j0 = max(i0, 0), max(j0, 0)
            i1, j1 = min(i1, nx - 1), min(j1, ny - 1)
            for i in range(i0, i1 + 1):
                for j in range(j0, j1 + 1):
                    (e_lists if k < len(seg) else c_lists)[i * ny + j].append(
                        k if k < len(seg) else k - len(seg))
        # reference points: cell centres, nudged off any edge
        ii, jj = np.divmod(np.arange(C), ny)
        ref = self.origin + (np.stack([ii, jj], axis=1) + 0.5) * h
        polys = [g for g in world.geoms]
        poly_arr = np.array(polys, dtype=object) if polys else np.empty(0, object)
        is_circ = np.asarray(world.is_circle, dtype=bool)
        if len(seg):
            lines = shapely.linestrings(seg)
            tree = shapely.STRtree(lines)
            for k in range(8):              # alternate: stays within 0.13 h of the centre
                near = tree.query(shapely.points(ref), predicate="dwithin",
                                  distance=1e-9 * max(h, 1.0))[0]
                if len(near) == 0:
                    break
                bump = (-1) ** k * np.array([0.1234567, 0.0765432]) * h
                ref[np.unique(near)] += bump
        ref_tree = shapely.STRtree(poly_arr)
        ci, pj = ref_tree.query(shapely.points(ref), predicate="within") if len(polys) \
            else (np.zeros(0, int), np.zeros(0, int))
        keep = ~is_circ[pj] if len(pj) else np.zeros(0, bool)
        ci, pj = ci[keep], pj[keep]
        contain = [[] for _ in range(C)]
        for c_, p_ in zip(ci, pj):
            contain[c_].append(int(p_))
        p_lists, in_lists = [], []
        for c_ in range(C):
            ps = sorted(set(int(owner[e]) for e in e_lists[c_]) | set(contain[c_]))
            inside = set(contain[c_])
            p_lists.append(ps)
            in_lists.append([p in inside for p in ps])
        self.K = max((len(v) for v in e_lists), default=0)
        self.Kc = max((len(v) for v in c_lists), default=0)
        self.P = max((len(v) for v in p_lists), default=0)
        self.cell_edges = _pad_rows(e_lists, self.K)
        self.cell_circles = _pad_rows(c_lists, self.Kc)
        self.cell_polys = _pad_rows(p_lists, self.P)
        rin = np.zeros((C, max(self.P, 1)), dtype=bool)
        for c_, v in enumerate(in_lists):
            rin[c_, :len(v)] = v
        self.cell_ref_in = rin
        self.cell_ref = ref

    def __repr__(self):
        return (f"EdgeGrid({self.n_edges} edges, {self.n_circles} circles, grid "
                f"{self.shape[0]}x{self.shape[1]} of {self.cell:g} m, K={self.K}, "
                f"Kc={self.Kc}, P={self.P})")

    # ------------------------------------------------------------ lookups
    def cell_of(self, points, xp=np):
        """Cell index (N,) of each point (clamped) and whether it lies in the grid."""
        g = (points[:, :2] - xp.asarray(self.origin, dtype=points.dtype)) / self.cell
        ij = xp.floor(g)
        nx, ny = self.shape
        ok = (ij[:, 0] >= 0) & (ij[:, 0] < nx) & (ij[:, 1] >= 0) & (ij[:, 1] < ny)
        i = xp.clip(ij[:, 0], 0, nx - 1).astype(np.int32)
        j = xp.clip(ij[:, 1], 0, ny - 1).astype(np.int32)
        return i * ny + j, ok

    def candidate_edges(self, points, xp=np):
        """(N, K) candidate edge indices (``-1`` where none) and the cell (N,)."""
        cell, ok = self.cell_of(points, xp)
        e = xp.asarray(self.cell_edges)[cell]
        return xp.where(ok[:, None], e, -1), cell, ok

    def candidate_circles(self, points, xp=np):
        cell, ok = self.cell_of(points, xp)
        e = xp.asarray(self.cell_circles)[cell]
        return xp.where(ok[:, None], e, -1)

    # ------------------------------------------------------------ queries
    def inside(self, points, xp=np):
        """(N, P) polygon ids of the point's cell (``-1`` padded) and (N, P)
        bool: the point is inside that polygon (circles excluded)."""
        e, cell, ok = self.candidate_edges(points, xp)
        seg = xp.asarray(self.seg)[xp.where(e >= 0, e, self.n_edges)]      # (N, K, 2, 2)
        own = xp.asarray(self.owner)[xp.where(e >= 0, e, self.n_edges)]
        ref = xp.asarray(self.cell_ref)[cell]
        qx, qy = points[:, 0:1], points[:, 1:2]
        cr = path_crosses(qx, qy, ref[:, 0:1], ref[:, 1:2], seg[..., 0, 0], seg[..., 0, 1],
                          seg[..., 1, 0], seg[..., 1, 1], xp) & (e >= 0)     # (N, K)
        polys = xp.asarray(self.cell_polys)[cell]                            # (N, P)
        rin = xp.asarray(self.cell_ref_in)[cell]
        match = (own[:, None, :] == polys[:, :, None]) & cr[:, None, :]     # (N, P, K)
        parity = (xp.sum(match.astype(np.int32), axis=-1) % 2) == 1
        inside = (rin != parity) & (polys >= 0) & ok[:, None]
        return xp.where(ok[:, None], polys, -1), inside

    def disc_hits(self, points, radius, xp=np):
        """Discs (centres (N, 2), radii (N,) or scalar) against every obstacle.

        Returns ``(hit (N,) bool, first (N,) int32)``: the disc touches or
        overlaps an obstacle (closed sets), and the lowest obstacle index
        touched (``-1`` if none). Exact for ``radius <= reach``.
        """
        big = np.int32(np.iinfo(np.int32).max)
        r = xp.broadcast_to(xp.asarray(radius, dtype=points.dtype), points.shape[:1])
        if self.dense:
            return disc_hits_dense(self, points, r, big, xp)
        first = xp.full(points.shape[:1], big, dtype=np.int32)
        if self.n_edges:
            e, cell, ok = self.candidate_edges(points, xp)
            ee = xp.where(e >= 0, e, self.n_edges)
            seg = xp.asarray(self.seg)[ee]
            own = xp.asarray(self.owner)[ee]
            d = point_segment_distance(points[:, 0:1], points[:, 1:2], seg[..., 0, 0],
                                       seg[..., 0, 1], seg[..., 1, 0], seg[..., 1, 1], xp)
            touch = (e >= 0) & (d <= r[:, None])
            first = xp.minimum(first, xp.min(xp.where(touch, own, big), axis=1))
            polys, inside = self.inside(points, xp)
            first = xp.minimum(first, xp.min(xp.where(inside, polys, big), axis=1))
        if self.n_circles:
            c = self.candidate_circles(points, xp)
            cc = xp.where(c >= 0, c, self.n_circles)
            cen = xp.asarray(self.circle_center)[cc]
            dist = _norm(cen[..., 0] - points[:, 0:1], cen[..., 1] - points[:, 1:2], xp)
            touch = (c >= 0) & (dist <= r[:, None] + xp.asarray(self.circle_radius)[cc])
            own = xp.asarray(self.circle_owner)[cc]
            first = xp.minimum(first, xp.min(xp.where(touch, own, big), axis=1))
        hit = first < big
        return hit, xp.where(hit, first, -1)

    def polygon_hits(self, verts, center, margin, xp=np):
        """Posed polygons ``verts`` (N, V, 2) around ``center`` (N, 2) (every
        vertex within ``reach - margin`` of it) against every obstacle.

        Returns ``(hit (N,), first (N,) int32)`` like :meth:`disc_hits`:
        ``dist(polygon, obstacle) <= margin`` (touching or overlapping).
        """
        big = np.int32(np.iinfo(np.int32).max)
        n = verts.shape[0]
        first = xp.full((n,), big, dtype=np.int32)
        m = xp.asarray(margin, dtype=verts.dtype)
        fx0, fy0 = verts[..., 0], verts[..., 1]                            # (N, V)
        fx1, fy1 = xp.roll(fx0, -1, axis=-1), xp.roll(fy0, -1, axis=-1)
        if self.n_edges:
            e, _, _ = self.candidate_edges(center, xp)
            ee = xp.where(e >= 0, e, self.n_edges)
            seg = xp.asarray(self.seg)[ee]                                 # (N, K, 2, 2)
            own = xp.asarray(self.owner)[ee]
            d2 = segment_segment_dist2(
                fx0[:, :, None], fy0[:, :, None], fx1[:, :, None], fy1[:, :, None],
                seg[:, None, :, 0, 0], seg[:, None, :, 0, 1], seg[:, None, :, 1, 0],
                seg[:, None, :, 1, 1], xp)                                 # (N, V, K)
            touch = (e >= 0) & ((xp.min(d2, axis=1) <= m * m)
                                | point_in_ring(seg[..., 0, 0], seg[..., 0, 1], verts, xp))
            first = xp.minimum(first, xp.min(xp.where(touch, own, big), axis=1))
            polys, inside = self.inside(verts[:, 0, :], xp)
            first = xp.minimum(first, xp.min(xp.where(inside, polys, big), axis=1))
        if self.n_circles:
            c = self.candidate_circles(center, xp)
            cc = xp.where(c >= 0, c, self.n_circles)
            cen = xp.asarray(self.circle_center)[cc]                       # (N, Kc, 2)
            rad = xp.asarray(self.circle_radius)[cc]
            d = point_segment_distance(cen[:, None, :, 0], cen[:, None, :, 1],
                                       fx0[:, :, None], fy0[:, :, None],
                                       fx1[:, :, None], fy1[:, :, None], xp)
            inn = point_in_ring(cen[..., 0], cen[..., 1], verts, xp)
            touch = (c >= 0) & ((xp.min(d, axis=1) <= rad + m) | inn)
            own = xp.asarray(self.circle_owner)[cc]
            first = xp.minimum(first, xp.min(xp.where(touch, own, big), axis=1))
        hit = first < big
        return hit, xp.where(hit, first, -1)

    def exceeded(self, need):
        """A sentence when a query asked for more than ``reach`` (else None)."""
        r = float(np.max(np.asarray(need.reach)))
        if r > self.reach * (1 + 1e-6) + 1e-12:      # float32 rounding is no overflow
            return (f"an obstacle query asked for radius {r:g}, the edge grid was built "
                    f"for {self.reach:g}")
        return None
