"""Neighbour queries over agent positions (k-d tree, never an N^2 loop).

The neighbour format that controllers consume: an ``(N, K)`` int64 array of
agent indices, padded with ``-1``, sorted by distance; ``idx >= 0`` is the
mask. ``K`` is fixed (``k_max``) so shapes stay static.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree


def radius_neighbors(pos, radius, k_max):
    """Up to ``k_max`` nearest other agents within ``radius`` of each agent.

    Parameters
    ----------
    pos : (N, D) array
    radius : float
    k_max : int

    Returns
    -------
    idx : (N, k_max) int64, padded with -1, nearest first
    dist : (N, k_max) float, ``inf`` where padded
    """
    pos = np.asarray(pos, dtype=float)
    n = pos.shape[0]
    k = min(int(k_max) + 1, n)
    tree = cKDTree(pos)
    dist, idx = tree.query(pos, k=k, distance_upper_bound=radius)
    dist = dist.reshape(n, k)
    idx = idx.reshape(n, k)
    # drop self (distance 0 to itself; with duplicates the self index may be
    # second, so remove it by identity)
    self_col = idx == np.arange(n)[:, None]
    keep = ~self_col
    # shift rows left where self was found; each row has at most one self entry
    order = np.argsort(~keep, axis=1, kind="stable")
    idx = np.take_along_axis(idx, order, axis=1)[:, : k - 1] if k > 1 else idx[:, :0]
    dist = np.take_along_axis(dist, order, axis=1)[:, : k - 1] if k > 1 else dist[:, :0]
    missing = ~np.isfinite(dist) | (idx >= n)
    idx = np.where(missing, -1, idx).astype(np.int64)
    dist = np.where(missing, np.inf, dist)
    if idx.shape[1] < k_max:
        pad = k_max - idx.shape[1]
        idx = np.pad(idx, ((0, 0), (0, pad)), constant_values=-1)
        dist = np.pad(dist, ((0, 0), (0, pad)), constant_values=np.inf)
    return idx, dist


def knn(pos, k):
    """The ``k`` nearest other agents of each agent (no range limit)."""
    return radius_neighbors(pos, np.inf, k)
