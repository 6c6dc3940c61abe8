r"""Axis-aligned rectangles in closed form: the cheap path for small worlds.

A rectangle whose sides are parallel to the axes (``rectangle``, the
walls of a ``World``) is four edges to the generic kernels of
:mod:`~avblocks.environment.edges`; as a box ``[x0, x1] x [y0, y1]`` each
query about it is one expression in ``x`` and one in ``y``, with no
division per edge and no per-edge ``where``:

- ray ``o + t u`` (slab method): with ``t_x = (x_k - o_x) / u_x`` at both
  sides, ``t_near = max(min t_x, min t_y)``, ``t_far = min(max t_x,
  max t_y)``; the ray meets the closed box when ``t_near <= t_far`` and
  ``t_far >= 0``, first at ``t_near``, or at ``t_far`` (the exit) when the
  origin is inside: the first edge crossed, what the edge kernel returns
  for the box's four edges. A zero component ``u_x = 0`` is taken as a
  tiny positive one (``1 / u_x = 1e30``), the limit the slabs tend to;
  the hits it gives are beyond any range sensor's reach unless the origin
  lies in the slab;
- distance from a point to the box's boundary (the least of the four
  point-to-edge distances): with ``d_x = max(x0 - p_x, p_x - x1)`` and
  ``d_y`` alike, ``|(max(d_x, 0), max(d_y, 0))|`` outside and ``-max(d_x,
  d_y)`` inside (the nearest side);
- disc ``|q - c| <= r`` against the closed box: ``max(d_x, 0)^2 +
  max(d_y, 0)^2 <= r^2`` (0 inside: containment counts).

:func:`split_boxes` finds the boxes among a world's edges; the other
polygons keep their edges (the ``rest``). ``EdgeGrid`` holds both and
answers queries densely (every agent against every box and every other
edge: no per-cell gathers) when the world is small (``DENSE_ITEMS``).
"""

from __future__ import annotations

import numpy as np

from ..utility.arrays import fold
from .kernels import _norm, point_in_polygons, point_segment_distance

#: Worlds with at most this many boxes + other edges + circles are queried
#: densely (every agent against every item): under ``vmap`` the gathers of
#: a cell's candidates cost more than testing a few dozen items outright
#: (the navigation task's disc test, 7 boxes, 1024 copies: 1 ms against 21
#: ms through the cells per 60-step rollout, CPU time of one XLA thread).
DENSE_ITEMS = 32

#: ``1 / u`` for a ray component that is exactly 0 (see the module docstring).
_INV_ZERO = 1e30


def split_boxes(seg, owner):
    """``(boxes (B, 4) [x0, y0, x1, y1], box_owner (B,), rest (E',) edge
    indices)``: the polygons made of exactly four axis-parallel edges
    spanning a rectangle of positive area, and the indices of every other
    edge. ``seg`` (E, 2, 2), ``owner`` (E,)."""
    seg = np.asarray(seg, dtype=float).reshape(-1, 2, 2)
    owner = np.asarray(owner)
    boxes, box_owner, rest = [], [], []
    for o in np.unique(owner):
        k = np.flatnonzero(owner == o)
        s = seg[k]
        xs, ys = np.unique(s[..., 0]), np.unique(s[..., 1])
        axis = (s[:, 0, 0] == s[:, 1, 0]) | (s[:, 0, 1] == s[:, 1, 1])
        if len(k) == 4 and len(xs) == 2 and len(ys) == 2 and axis.all():
            boxes.append([xs[0], ys[0], xs[1], ys[1]])
            box_owner.append(o)
        else:
            rest.extend(k.tolist())
    return (np.asarray(boxes, dtype=float).reshape(-1, 4),
            np.asarray(box_owner, dtype=np.int32), np.asarray(rest, dtype=np.int64))


def inverse_direction(u, xp=np):
    """``1 / u`` with an exact zero taken as a tiny positive component."""
    return 1.0 / xp.where(u == 0, 1.0 / _INV_ZERO, u)


def ray_boxes(ox, oy, ix, iy, x0, y0, x1, y1, xp=np):
    """Hit distance of rays (origin ``o``, inverse direction ``ix, iy``: see
    :func:`inverse_direction`) on boxes: the entry, or the exit when the
    origin is inside; ``inf`` on a miss. Broadcasts."""
    ax, bx = (x0 - ox) * ix, (x1 - ox) * ix
    ay, by = (y0 - oy) * iy, (y1 - oy) * iy
    near = xp.maximum(xp.minimum(ax, bx), xp.minimum(ay, by))
    far = xp.minimum(xp.maximum(ax, bx), xp.maximum(ay, by))
    t = xp.where(near >= 0, near, far)
    return xp.where((near <= far) & (far >= 0), t, xp.inf)


def _excess(px, py, x0, y0, x1, y1, xp):
    return xp.maximum(x0 - px, px - x1), xp.maximum(y0 - py, py - y1)


def box_dist2(px, py, x0, y0, x1, y1, xp=np):
    """Squared distance from points to the closed boxes (0 inside). Broadcasts."""
    dx, dy = _excess(px, py, x0, y0, x1, y1, xp)
    dx, dy = xp.maximum(dx, 0.0), xp.maximum(dy, 0.0)
    return dx * dx + dy * dy


def box_boundary_distance(px, py, x0, y0, x1, y1, xp=np):
    """Distance from points to the boxes' boundaries (inside: to the
    nearest side), the least of the four point-to-edge distances; a finite
    gradient everywhere but on the boundary. Broadcasts."""
    dx, dy = _excess(px, py, x0, y0, x1, y1, xp)
    ox, oy = xp.maximum(dx, 0.0), xp.maximum(dy, 0.0)
    s = ox * ox + oy * oy
    out = s > 0
    return xp.where(out, xp.sqrt(xp.where(out, s, 1.0)), -xp.maximum(dx, dy))


def boundary_distance(px, py, boxes, rest_seg, xp=np):
    """Least distance from points ``(px, py)`` (..., N, 1) to the boundary of
    any box ``boxes`` (B, 4) or edge ``rest_seg`` (E', 4): (..., N)."""
    big = xp.full(px.shape[:-1], xp.inf, dtype=px.dtype)
    if len(boxes):
        b = boxes
        d = box_boundary_distance(px, py, b[:, 0], b[:, 1], b[:, 2], b[:, 3], xp)
        big = xp.minimum(big, fold(xp.minimum, d, -1, xp))
    if len(rest_seg):
        s = rest_seg
        d = point_segment_distance(px, py, s[:, 0], s[:, 1], s[:, 2], s[:, 3], xp)
        big = xp.minimum(big, fold(xp.minimum, d, -1, xp))
    return big


def disc_hits_dense(grid, points, r, big, xp=np):
    """``EdgeGrid.disc_hits`` with every box, edge and circle of the grid's
    world tested (no cell lookup): boxes in closed form, the other
    polygons by their edges and a crossing-number inside test, circles by
    their centres. ``r`` (N,), ``big``: the int32 "none" sentinel."""
    first = xp.full(points.shape[:1], big, dtype=np.int32)
    px, py = points[:, 0:1], points[:, 1:2]

    def lowest(touch, own):
        return fold(xp.minimum, xp.where(touch, xp.asarray(own), big), 1, xp)
    if len(grid.boxes):
        b = xp.asarray(grid.boxes, dtype=points.dtype)
        d2 = box_dist2(px, py, b[:, 0], b[:, 1], b[:, 2], b[:, 3], xp)       # (N, B)
        first = xp.minimum(first, lowest(d2 <= (r * r)[:, None], grid.box_owner))
    if len(grid.rest):
        s = xp.asarray(grid.seg[grid.rest], dtype=points.dtype)              # (E', 2, 2)
        own = grid.owner[grid.rest]
        d = point_segment_distance(px, py, s[:, 0, 0], s[:, 0, 1], s[:, 1, 0], s[:, 1, 1],
                                   xp)
        first = xp.minimum(first, lowest(d <= r[:, None], own))
        inside = point_in_polygons(points, s, own, grid.n_obstacles, xp)      # (N, M)
        first = xp.minimum(first, lowest(inside, np.arange(grid.n_obstacles)))
    if grid.n_circles:
        cen = xp.asarray(grid.circle_center[:-1], dtype=points.dtype)
        rad = xp.asarray(grid.circle_radius[:-1], dtype=points.dtype)
        dist = _norm(cen[:, 0] - px, cen[:, 1] - py, xp)
        first = xp.minimum(first, lowest(dist <= r[:, None] + rad, grid.circle_owner[:-1]))
    hit = first < big
    return hit, xp.where(hit, first, -1)
