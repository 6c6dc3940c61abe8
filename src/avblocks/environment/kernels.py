"""The ``xp`` geometry kernels on edges, circles and polygons (traceable by
JAX; each broadcasts element-wise). Formulas: see
:mod:`avblocks.environment.edges`, which re-exports them."""

from __future__ import annotations

import numpy as np


# ----------------------------------------------------------------- kernels
def _cross(ax, ay, bx, by):
    return ax * by - ay * bx


def _norm(x, y, xp):
    """``sqrt(x^2 + y^2)`` with a finite gradient at 0 (the double ``where``)."""
    s = x * x + y * y
    pos = s > 0
    return xp.where(pos, xp.sqrt(xp.where(pos, s, 1.0)), 0.0)


def point_segment_distance(px, py, ax, ay, bx, by, xp=np):
    """Distance from points ``(px, py)`` to segments ``a b`` (broadcast).

    Past either end: the distance to that end; otherwise the perpendicular
    distance ``|(p - a) x (b - a)| / |b - a|`` (exactly 0 for a point on the
    segment's line, as GEOS computes it)."""
    ex, ey = bx - ax, by - ay
    wx, wy = px - ax, py - ay
    ee = ex * ex + ey * ey
    ee_s = xp.where(ee > 0, ee, 1.0)
    t = (wx * ex + wy * ey) / ee_s
    da = _norm(wx, wy, xp)
    db = _norm(px - bx, py - by, xp)
    dp = xp.abs(_cross(wx, wy, ex, ey)) / xp.sqrt(ee_s)
    return xp.where((t <= 0) | (ee <= 0), da, xp.where(t >= 1, db, dp))


def path_crosses(qx, qy, cx, cy, ax, ay, bx, by, xp=np):
    """Whether segment ``a b`` crosses the path ``q -> c`` (half-open rule in
    the path's frame; see the module docstring). Broadcasts."""
    dx, dy = cx - qx, cy - qy
    sa = _cross(dx, dy, ax - qx, ay - qy)
    sb = _cross(dx, dy, bx - qx, by - qy)
    straddle = (sa > 0) != (sb > 0)
    den = sb - sa                                  # = d x (b - a), != 0 when straddling
    num = _cross(ax - qx, ay - qy, bx - ax, by - ay)
    den_s = xp.where(straddle, den, 1.0)
    t = num / den_s
    return straddle & (t >= 0) & (t <= 1)


def ray_segment(ox, oy, ux, uy, ax, ay, bx, by, xp=np, eps=1e-12):
    """Hit distance of rays (origin ``o``, unit direction ``u``) on segments
    ``a b``; ``inf`` on a miss. Broadcasts."""
    ex, ey = bx - ax, by - ay
    wx, wy = ax - ox, ay - oy
    den = ux * ey - uy * ex
    ok_den = xp.abs(den) > eps
    inv = 1.0 / xp.where(ok_den, den, 1.0)
    t = (wx * ey - wy * ex) * inv
    s = (wx * uy - wy * ux) * inv
    ok = ok_den & (t >= 0) & (s >= -eps) & (s <= 1 + eps)
    return xp.where(ok, t, xp.inf)


def ray_circle(ox, oy, ux, uy, cx, cy, r, xp=np):
    """Hit distance of rays on circles (centre ``c``, radius ``r``); 0 when
    the origin is inside, ``inf`` on a miss. Broadcasts."""
    fx, fy = cx - ox, cy - oy
    tca = fx * ux + fy * uy
    ff = fx * fx + fy * fy
    d2 = ff - tca * tca
    r2 = r * r
    disc = r2 - d2
    pos = disc > 0
    thc = xp.where(pos, xp.sqrt(xp.where(pos, disc, 1.0)), 0.0)
    inside = ff <= r2
    ok = inside | ((d2 <= r2) & (tca - thc >= 0))
    return xp.where(ok, xp.where(inside, 0.0, tca - thc), xp.inf)


def point_segment_dist2(px, py, ax, ay, bx, by, xp=np):
    """Squared :func:`point_segment_distance` (no square root: cheaper for
    ``<=`` tests)."""
    ex, ey = bx - ax, by - ay
    wx, wy = px - ax, py - ay
    ee = ex * ex + ey * ey
    ee_s = xp.where(ee > 0, ee, 1.0)
    t = (wx * ex + wy * ey) / ee_s
    vx, vy = px - bx, py - by
    c = _cross(wx, wy, ex, ey)
    return xp.where((t <= 0) | (ee <= 0), wx * wx + wy * wy,
                    xp.where(t >= 1, vx * vx + vy * vy, c * c / ee_s))


def segment_segment_dist2(a0x, a0y, a1x, a1y, b0x, b0y, b1x, b1y, xp=np):
    """Squared distance between segments ``a0 a1`` and ``b0 b1`` (broadcast):
    0 when they meet (closed segments), else the least of the four squared
    endpoint-to-segment distances."""
    o1 = _cross(a1x - a0x, a1y - a0y, b0x - a0x, b0y - a0y)
    o2 = _cross(a1x - a0x, a1y - a0y, b1x - a0x, b1y - a0y)
    o3 = _cross(b1x - b0x, b1y - b0y, a0x - b0x, a0y - b0y)
    o4 = _cross(b1x - b0x, b1y - b0y, a1x - b0x, a1y - b0y)
    collinear = (o1 == 0) & (o2 == 0) & (o3 == 0) & (o4 == 0)
    meet = (o1 * o2 <= 0) & (o3 * o4 <= 0) & ~collinear
    d = xp.minimum(
        xp.minimum(point_segment_dist2(a0x, a0y, b0x, b0y, b1x, b1y, xp),
                   point_segment_dist2(a1x, a1y, b0x, b0y, b1x, b1y, xp)),
        xp.minimum(point_segment_dist2(b0x, b0y, a0x, a0y, a1x, a1y, xp),
                   point_segment_dist2(b1x, b1y, a0x, a0y, a1x, a1y, xp)))
    return xp.where(meet, 0.0, d)


def segment_segment_distance(a0x, a0y, a1x, a1y, b0x, b0y, b1x, b1y, xp=np):
    """Distance between segments ``a0 a1`` and ``b0 b1`` (broadcast): 0 when
    they meet (closed segments), else the least of the four endpoint-to-
    segment distances."""
    d2 = segment_segment_dist2(a0x, a0y, a1x, a1y, b0x, b0y, b1x, b1y, xp)
    pos = d2 > 0
    return xp.where(pos, xp.sqrt(xp.where(pos, d2, 1.0)), 0.0)


def point_in_ring(px, py, ring, xp=np):
    """Points strictly inside closed vertex loops (crossing number, ray to +x).

    ``px, py`` (..., Q); ``ring`` (..., V, 2) with the loop's vertices (not
    repeated), broadcast against the points' leading axes. Returns (..., Q).
    """
    ax, ay = ring[..., None, :, 0], ring[..., None, :, 1]               # (..., 1, V)
    bx = xp.roll(ring[..., 0], -1, axis=-1)[..., None, :]
    by = xp.roll(ring[..., 1], -1, axis=-1)[..., None, :]
    qx, qy = px[..., None], py[..., None]                               # (..., Q, 1)
    straddle = (ay > qy) != (by > qy)
    dy = xp.where(straddle, by - ay, 1.0)
    xint = ax + (qy - ay) * (bx - ax) / dy
    cnt = xp.sum((straddle & (xint > qx)).astype(np.int32), axis=-1)
    return (cnt % 2) == 1


def point_in_polygons(points, seg, owner, n_poly, xp=np):
    """(N, M) bool: point ``i`` strictly inside polygon ``m`` (crossing number
    of the ray towards +x against every edge; holes count as edges of their
    polygon). Brute force over all E edges: for tests and small worlds.
    Points on a boundary may go either way."""
    px, py = points[:, 0:1], points[:, 1:2]
    ax, ay, bx, by = seg[None, :, 0, 0], seg[None, :, 0, 1], seg[None, :, 1, 0], \
        seg[None, :, 1, 1]
    straddle = (ay > py) != (by > py)
    dy = xp.where(straddle, by - ay, 1.0)
    xint = ax + (py - ay) * (bx - ax) / dy
    c = straddle & (xint > px)                                   # (N, E)
    onehot = owner[:, None] == xp.arange(n_poly)[None, :]        # (E, M)
    cnt = c.astype(np.int32) @ onehot.astype(np.int32)
    return (cnt % 2) == 1
