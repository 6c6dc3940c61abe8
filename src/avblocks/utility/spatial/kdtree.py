"""The NumPy engine's k nearest and radius queries: SciPy's k-d tree with
the cell list's exact results (same neighbours, same order, same distances)."""

from __future__ import annotations

import numpy as np

from .cells import CellList
from .layout import layout
from .queries import nearest

#: cKDTree built by sliding midpoints, node boxes not shrunk to the points:
#: built 2.4x faster at 10^4 points than SciPy's default and queried as fast
#: on the flocking benchmark's lattice (the answers do not depend on the
#: tree's shape: :func:`kd_nearest` orders ties itself)
_FAST_BUILD = {"balanced_tree": False, "compact_nodes": False}

#: points from which :func:`kd_nearest` queries the tree on every core
#: (SciPy's ``workers=-1``; the same answers): the query of 10^7 agents is
#: the second largest part of planning a compiled run of them on the host
#: (one NumPy evaluation at t0; 1e6 points 2.12 -> 1.47 s on 2 cores).
#: Below it the NumPy engine stays on one thread, as its benchmarks
#: measure it.
PARALLEL_QUERY = 2 ** 18


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
        tree = cKDTree(pts, boxsize=b, **_FAST_BUILD)
    else:
        tree = cKDTree(pts, **_FAST_BUILD)
    kq = min(k + 2, n)
    d, j = tree.query(pts, k=kq, distance_upper_bound=np.nextafter(float(radius), np.inf),
                      workers=-1 if n >= PARALLEL_QUERY else 1)
    d, j = d.reshape(n, kq), j.reshape(n, kq)
    if exclude_self and np.array_equal(j[:, 0], np.arange(n)):
        j, d, amb = _others_sorted(d, j, k, n)
    else:
        j, d, amb = _general(d, j, k, n, exclude_self)
    if amb.size:
        cells = CellList(float(radius), box=box, dim=pts.shape[1])
        ai, ad, _ = nearest(cells, pts, radius, k, pts[amb], np,
                            ids=amb if exclude_self else None)
        j[amb], d[amb] = ai, ad
    return j, d


def _tie_order(d, j):
    """Rows with equal finite distances put in index order among them
    (the tree sorts by distance only); in place on ``d``, ``j``."""
    eq = d[:, 1:] == d[:, :-1]
    eq &= d[:, 1:] < np.inf
    tied = np.nonzero(eq.any(axis=1))[0]
    if tied.size:
        o = np.lexsort((j[tied], d[tied]), axis=-1)
        d[tied] = np.take_along_axis(d[tied], o, 1)
        j[tied] = np.take_along_axis(j[tied], o, 1)


def _others_sorted(d, j, k, n):
    """:func:`kd_nearest` from the tree's ``kq`` nearest (``d``, ``j``, (n,
    kq)) when every point is its own nearest (the usual case: no
    duplicates): the others are the columns after the first, already
    sorted by distance. ``(idx (n, k), dist (n, k), rows to answer again)``.
    """
    kq = d.shape[1]
    d, j = d[:, 1:], j[:, 1:]
    _tie_order(d, j)
    kk = min(k, kq - 1)
    if kq == k + 2 and kq < n:
        # a row holding k + 1 others whose k-th and (k+1)-th are as far may
        # have tied points the tree left out (the farthest returned is
        # d[:, k] exactly when the row is full)
        last = d[:, k]
        amb = np.nonzero((d[:, k - 1] == last) & (last < np.inf))[0]
    else:
        amb = np.zeros(0, np.int64)
    dk, jk = d[:, :kk], j[:, :kk]
    idx = np.where(jk < n, jk, -1).astype(np.int64, copy=False)
    dist = np.array(dk)
    if kk < k:
        idx = np.pad(idx, ((0, 0), (0, k - kk)), constant_values=-1)
        dist = np.pad(dist, ((0, 0), (0, k - kk)), constant_values=np.inf)
    return idx, dist, amb


def _general(d, j, k, n, exclude_self):
    """:func:`kd_nearest` from the tree's ``kq`` nearest, any rows (a point
    may not be its own nearest: duplicates), see :func:`_others_sorted`."""
    kq = d.shape[1]
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
    _tie_order(d, j)
    kk = min(k, kq)
    dk = d[:, kk - 1]
    amb = np.nonzero(full & np.isfinite(dk) & (dk == dmax))[0]
    d, j = d[:, :kk], j[:, :kk]
    j = np.where(np.isfinite(d), j, -1)
    if kk < k:
        j = np.pad(j, ((0, 0), (0, k - kk)), constant_values=-1)
        d = np.pad(d, ((0, 0), (0, k - kk)), constant_values=np.inf)
    return j.astype(np.int64), d, amb


def kd_within(points, radius, queries=None, *, exclude_self=True, reach=None):
    """:func:`within` in free space by SciPy's k-d tree (NumPy only): the
    same rows as the cell list's, entry for entry.

    ``(idx (Q, H), dist (Q, H))``: every point within ``radius`` (inclusive)
    of each query point, ``-1`` / ``inf`` padded, ``H`` the largest count.
    The tree proposes the pairs within a slightly larger radius; each is
    kept by the cell list's own test (``d2 = sum_a (p_j,a - q_a)^2 <=
    radius^2``) and distance (``sqrt(d2)``); a row lists its points in the
    order the cell list visits them (by cell key, then index: the cell
    list's sorted order, see :func:`layout`, for cells planned for
    ``reach``, default ``radius``).
    """
    from scipy.spatial import cKDTree
    pts = np.asarray(points, dtype=float)
    n = pts.shape[0]
    self_q = queries is None
    q = pts if self_q else np.asarray(queries, dtype=float)
    qn = q.shape[0]
    r = float(radius)
    if n == 0 or qn == 0:
        return np.full((qn, 1), -1, np.int64), np.full((qn, 1), np.inf)
    loose = r * (1.0 + 1e-9) + 1e-300
    tree = cKDTree(pts)
    if self_q:
        pr = tree.query_pairs(loose, output_type="ndarray")
        i = np.concatenate([pr[:, 0], pr[:, 1]])
        j = np.concatenate([pr[:, 1], pr[:, 0]])
        if not exclude_self:
            i = np.concatenate([i, np.arange(n)])
            j = np.concatenate([j, np.arange(n)])
    else:
        sm = cKDTree(q).sparse_distance_matrix(tree, loose, output_type="ndarray")
        i, j = sm["i"].astype(np.int64), sm["j"].astype(np.int64)
    d2 = 0.0
    for a in range(pts.shape[1]):
        da = pts[j, a] - q[i, a]
        d2 = d2 + da * da
    keep = d2 <= r * r
    i, j, d2 = i[keep], j[keep], d2[keep]
    # the cell list's visiting order: its sorted order of the points
    lay = layout(CellList(r if reach is None else float(reach), dim=pts.shape[1]), pts, np)
    rank = np.empty(n, np.int64)
    rank[lay.order] = np.arange(n)
    o = np.argsort(i * n + rank[j], kind="stable")
    i, j, d2 = i[o], j[o], d2[o]
    count = np.bincount(i, minlength=qn)
    width = max(1, int(count.max()) if count.size else 1)
    start = np.concatenate([[0], np.cumsum(count)[:-1]])
    col = np.arange(i.size) - start[i]
    idx = np.full((qn, width), -1, np.int64)
    dist = np.full((qn, width), np.inf)
    idx[i, col] = j
    dist[i, col] = np.sqrt(d2)
    return idx, dist
