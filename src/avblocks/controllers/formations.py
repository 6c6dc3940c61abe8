"""Formation helpers: leader trees and references for :class:`LeaderFollower`.

A formation is a set of body positions ``b_i`` (N, 2) in the formation frame
(x forward, y to the left), agent 0 the formation leader at the origin.
:func:`formation` turns it into the arrays LeaderFollower takes:

- ``leader[i]``: the agent ``i`` follows (-1 for agent 0);
- ``l_ref[i]``, ``alpha_ref[i]``: distance and tracking angle from the leader's
  centre to the follower's off-axis point ``b_i + d e_x`` (all headings equal
  to the formation heading), per eq. (2) of the AVLib paper:
  ``r = b_i + d e_x - b_leader``, ``l = |r|``, ``alpha = atan2(-r_y, -r_x)``.

Shapes (``spacing`` s between neighbours): ``line`` (abreast, centred on the
leader), ``column`` (single file), ``wedge`` (V, apex at the leader),
``diamond`` (a square lattice turned 45 degrees, filled ring by ring),
``grid`` (rows of ``ceil(sqrt(N))`` behind the leader) and
:func:`virtual_grid` (agents on given integer cells of a grid, as in the
virtual-grid formations of the AVLib case study IV.D).
"""

from __future__ import annotations

import math

import numpy as np

from ..core.errors import ParameterError

SHAPES = ("line", "column", "wedge", "diamond", "grid")


def _n(n):
    try:
        n = int(n)
    except (TypeError, ValueError):
        n = 0
    if n < 1:
        raise ParameterError("formation needs n >= 1 agents", param="n",
                             expected=">= 1", found=n)
    return n


def formation_offsets(shape, n, spacing=1.0):
    """Body positions (N, 2) of ``shape`` in the formation frame, agent 0 at 0."""
    n = _n(n)
    s = float(spacing)
    if not (math.isfinite(s) and s > 0):
        raise ParameterError("spacing must be > 0", param="spacing", found=spacing)
    k = np.arange(n)
    side = np.where(k % 2 == 1, 1.0, -1.0)           # odd: left, even: right
    rank = (k + 1) // 2                               # 0, 1, 1, 2, 2, ...
    if shape == "line":
        off = np.stack([np.zeros(n), side * rank * s], axis=-1)
    elif shape == "column":
        off = np.stack([-k * s, np.zeros(n)], axis=-1)
    elif shape == "wedge":
        off = np.stack([-rank * s, side * rank * s], axis=-1)
    elif shape == "diamond":
        # the square lattice turned 45 degrees, points beside or behind the
        # leader, nearest first (n = 4 gives the classic diamond)
        m = int(math.ceil(math.sqrt(n))) + 2
        i, j = np.meshgrid(np.arange(-m, m + 1), np.arange(-m, m + 1), indexing="ij")
        c = math.sqrt(0.5)
        px, py = (c * (i - j)).ravel(), (c * (i + j)).ravel()
        keep = px <= 1e-9
        px, py = px[keep], py[keep]
        order = np.lexsort((py, -px, np.abs(py), np.round(np.hypot(px, py), 9)))
        off = s * np.stack([px[order], py[order]], axis=-1)[:n]
    elif shape == "grid":
        cols = int(math.ceil(math.sqrt(n)))
        row, col = k // cols, k % cols
        off = np.stack([-row * s, (col - (cols - 1) / 2) * s], axis=-1)
        off = off - off[0]
    else:
        raise ParameterError("unknown formation shape", param="shape",
                             expected=SHAPES, found=shape)
    return off + 0.0


def virtual_grid(cells, spacing=1.0):
    """Body positions from integer grid cells (N, 2) (row back, column left);
    cell 0 is the leader's."""
    c = np.asarray(cells, dtype=float)
    if c.ndim != 2 or c.shape[1] != 2 or c.shape[0] < 1:
        raise ParameterError("cells must be (N, 2)", param="cells", found=c.shape)
    off = np.stack([-c[:, 0], c[:, 1]], axis=-1) * float(spacing)
    return off - off[0]


def leader_tree(offsets, tree="nearest"):
    """Leader array for body positions ``offsets`` (N, 2).

    ``"star"``: everyone follows agent 0. ``"chain"``: agent i follows i-1.
    ``"nearest"``: agent i follows the nearest agent among 0..i-1 (ties to
    the lower index): short links, a tree whose depth grows with the shape.
    """
    off = np.asarray(offsets, dtype=float)
    n = off.shape[0]
    leader = np.full(n, -1, dtype=np.int64)
    if n == 1:
        return leader
    if tree == "star":
        leader[1:] = 0
    elif tree == "chain":
        leader[1:] = np.arange(n - 1)
    elif tree == "nearest":
        # a block of rows at a time: about 2^18 distances in memory, where
        # all N^2 at once took about 22 GB for 30,000 agents
        rows = max(1, (1 << 18) // n)
        for a in range(1, n, rows):
            b = min(n, a + rows)
            dist = np.linalg.norm(off[a:b, None, :] - off[None, :b, :], axis=-1)
            earlier = np.arange(b)[None, :] < np.arange(a, b)[:, None]
            leader[a:b] = np.argmin(np.where(earlier, dist, np.inf), axis=1)
    else:
        raise ParameterError("unknown tree", param="tree",
                             expected=("star", "chain", "nearest"), found=tree)
    return leader


def references(offsets, leader, d=0.1):
    """``(l_ref, alpha_ref)`` (N,) placing each follower's body at its offset."""
    off = np.asarray(offsets, dtype=float)
    leader = np.asarray(leader)
    lead = np.where(leader >= 0, leader, np.arange(len(off)))
    r = off + np.array([float(d), 0.0]) - off[lead]
    l_ref = np.hypot(r[:, 0], r[:, 1])
    alpha_ref = np.arctan2(-r[:, 1], -r[:, 0]) + 0.0     # no -0.0
    root = leader < 0
    return np.where(root, 0.0, l_ref), np.where(root, 0.0, alpha_ref)


def formation(shape, n, spacing=1.0, *, tree="nearest", d=0.1):
    """``(leader, l_ref, alpha_ref)`` for LeaderFollower: ``shape`` in SHAPES.

    >>> leader, l_ref, a_ref = formation("column", 3, 2.0, d=0.0)
    >>> leader.tolist(), l_ref.tolist(), a_ref.tolist()
    ([-1, 0, 1], [0.0, 2.0, 2.0], [0.0, 0.0, 0.0])
    """
    off = formation_offsets(shape, n, spacing)
    leader = leader_tree(off, tree)
    l_ref, alpha_ref = references(off, leader, d)
    return leader, l_ref, alpha_ref
