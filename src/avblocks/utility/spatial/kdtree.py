"""The NumPy engine's k nearest: SciPy's k-d tree with the cell list's exact
order (ties by index)."""

from __future__ import annotations

import numpy as np

from .cells import CellList
from .queries import nearest


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
