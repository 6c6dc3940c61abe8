"""Array helpers the task blocks and their scenarios share (both engines):
the other agents of each agent, pairwise distances, row sorts without a
gather, and seed-driven start positions that trace."""

from __future__ import annotations

import numpy as np

from avblocks.utility.arrays import fold, norm2


def others_index(n):
    """(n, n-1) int array: for agent i, the indices of the other agents."""
    if n < 2:
        return np.zeros((max(n, 1), 0), dtype=int)
    j = np.arange(n - 1)[None, :]
    return j + (j >= np.arange(n)[:, None])          # skip column i in row i


def pairwise(p, xp):
    """(..., n, n) distances between the rows of p (..., n, 2); diagonal = +inf."""
    d = p[..., :, None, :] - p[..., None, :, :]
    r = xp.sqrt(norm2(d) + 1e-12)
    n = p.shape[-2]
    return xp.where(np.eye(n, dtype=bool), xp.inf, r)


#: Rows up to this long are sorted by ranks (:func:`sort_rows`), longer by argsort.
RANK_SORT_MAX = 16


def drop_diagonal(q, xp):
    """(..., n, n, k) -> (..., n, n-1, k): row ``i`` without its column ``i``
    (the others in index order), from two shifted slices (no gather)."""
    n = q.shape[-2]
    i, j = np.arange(n)[:, None], np.arange(n - 1)[None, :]
    return xp.where((j >= i)[..., None], q[..., :, 1:, :], q[..., :, :-1, :])


def sort_rows(keys, parts, xp, slots=None):
    """``parts`` (each (..., m, k)) reordered along the ``m`` axis by
    ascending ``keys`` (..., m), ties in index order (a stable sort); only
    the first ``slots`` of the result (default all ``m``).

    Short rows (``m <= RANK_SORT_MAX``) go by ranks: ``rank_i = #{j: key_j
    < key_i, or key_j = key_i and j < i}``, then ``out[rank_i] = part[i]``
    as a sum of one-hot selections: elementwise work ``m^2`` per row, no
    sort operation and no gather (the navigation task's sort of the other
    agents at 1024 copies, 60 steps, CPU time of one XLA thread: 39 ms with
    ``argsort`` and ``take_along_axis``, 11 ms by ranks). Longer rows:
    ``argsort``."""
    m = keys.shape[-1]
    slots = m if slots is None else int(slots)
    if m > RANK_SORT_MAX:
        order = xp.argsort(keys, axis=-1)[..., :slots, None]
        return [xp.take_along_axis(q, order, axis=-2) for q in parts]
    i = np.arange(m)
    ki, kj = keys[..., :, None], keys[..., None, :]                     # (..., m, m)
    before = (kj < ki) | ((kj == ki) & (i[None, :] < i[:, None]))
    rank = fold(xp.add, before.astype(np.int32), -1, xp)               # (..., m)
    onehot = (rank[..., :, None] == i[:slots])[..., None]             # (..., m, slots, 1)
    return [fold(xp.add, xp.where(onehot, q[..., :, None, :], xp.zeros((), q.dtype)), -3, xp)
            for q in parts]


def uniform_points(key, n, half, xp, min_sep=0.0, tries=8):
    """``n`` points uniform in ``[-half, half]^2`` (rng keys; both engines).
    With ``min_sep`` the draw is repeated ``tries`` times and the candidate
    with the largest closest-pair distance is kept (no loop on values, so
    it traces)."""
    from avblocks.core import rng
    ks = rng.split(key, xp, tries)
    best, best_d = None, None
    for k in ks:
        p = rng.uniform(k, (n, 2), xp, -half, half)
        if min_sep <= 0 or n < 2:
            return p
        d = xp.min(pairwise(p, xp))
        if best is None:
            best, best_d = p, d
        else:
            better = d > best_d
            best = xp.where(better, p, best)
            best_d = xp.where(better, d, best_d)
    return best


def packing_bound(side, min_sep):
    """The most points that can lie pairwise at least ``min_sep`` apart in a
    square of ``side``: discs of radius ``min_sep / 2`` around them do not
    overlap and lie in the square grown by ``min_sep / 2``, so ``n <= (side +
    min_sep)^2 / (pi min_sep^2 / 4)``."""
    side = max(float(side), 0.0)
    return int((side + min_sep) ** 2 / (np.pi * min_sep ** 2 / 4))


def free_points(key, n, half, grid, clearance, xp, tries=24, min_sep=0.0):
    """``n`` points uniform in ``[-(half - clearance), half - clearance]^2``
    farther than ``clearance`` from every obstacle (``grid``: an
    :class:`~avblocks.environment.EdgeGrid` of the world built for reach >=
    ``clearance``; its closed disc test) and (best effort) ``min_sep``
    apart: ``tries`` candidates per point, the first that fits is kept
    (traceable). Separation is sought only while ``n`` points can be
    ``min_sep`` apart at all (:func:`packing_bound`; 66 in the navigation
    arena): its pass is quadratic in ``n`` (a scenario file asking for two
    million agents used to take hours here)."""
    from avblocks.core import rng
    c = rng.uniform(key, (tries, n, 2), xp, -(half - clearance), half - clearance)
    ok = ~xp.reshape(grid.disc_hits(xp.reshape(c, (tries * n, 2)), clearance, xp)[0],
                     (tries, n))
    if min_sep <= 0 or n < 2 or n > packing_bound(2 * (half - clearance), min_sep):
        # (more points than fit min_sep apart in the square: the separation
        # cannot hold, and its pass, quadratic in n, is skipped)
        pick = xp.argmax(ok, axis=0)                            # first valid (or 0)
        return xp.take_along_axis(c, pick[None, :, None], axis=0)[0]
    # separation: agents pick in turn, each the first candidate that fits
    # the obstacles and the agents before it (n is small: reset only)
    chosen = []
    for i in range(n):
        oki = ok[:, i]
        for q in chosen:
            oki = oki & (xp.sum((c[:, i] - q) ** 2, -1) >= min_sep ** 2)
        chosen.append(c[xp.argmax(oki), i])
    return xp.stack(chosen)
