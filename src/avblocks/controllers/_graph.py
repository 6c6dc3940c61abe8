"""Where swarm controllers get their neighbour sets from.

Every swarm controller works on the standard neighbour format of
:mod:`avblocks.environment.neighbors`: an ``(N, K)`` int64 array of agent
indices padded with ``-1`` (``idx >= 0`` is the mask), optionally with
``(N, K)`` weights. Three sources are offered, chosen when the block is built:

``"port"`` (default)
    a ``neighbors`` input port (N, K) int64, e.g. from an environment
    Neighbors block; ``K`` is taken from whatever is wired to it.
``adjacency=A``
    a fixed communication graph: an (N, N) adjacency matrix (dense or
    scipy.sparse, weights allowed), turned once into padded neighbour lists.
``radius=r, k_max=K``
    the ``K`` nearest within ``r`` computed inside ``output()`` by a
    :class:`~avblocks.utility.spatial.NeighborSearch` the block owns (set as
    its attribute ``_neighbor_search``, so the compiled engine plans it):
    the k-d tree under NumPy, the traceable cell list under JAX (same
    neighbours, same order; positions in 2 or 3 dimensions).
"""

from __future__ import annotations

import numpy as np

from ..core.errors import ParameterError, ShapeError
from ..core.params import positive_scalar
from ..environment.neighbors import radius_neighbors
from ..utility.spatial import NeighborSearch


def adjacency_to_neighbors(adjacency, n, block):
    """Padded neighbour lists ``(idx, w)`` of shape (N, K) from an (N, N) matrix.

    Row ``i`` lists the ``j`` with ``A[i, j] != 0`` (``j != i``); ``K`` is the
    largest degree (at least 1).
    """
    try:
        import scipy.sparse as sp
        if sp.issparse(adjacency):
            a = sp.coo_array(adjacency)
            rows, cols, vals = a.row, a.col, a.data.astype(float)
            shape = a.shape
        else:
            dense = np.asarray(adjacency, dtype=float)
            shape = dense.shape
            if dense.ndim != 2:
                raise ValueError
            rows, cols = np.nonzero(dense)
            vals = dense[rows, cols]
    except (TypeError, ValueError):
        raise ParameterError("adjacency must be an (N, N) numeric matrix",
                             block=block, param="adjacency") from None
    if tuple(shape) != (n, n):
        raise ParameterError("adjacency has the wrong shape", block=block,
                             param="adjacency", expected=(n, n), found=tuple(shape))
    keep = (rows != cols) & (vals != 0)
    rows, cols, vals = rows[keep], cols[keep], vals[keep]
    if not np.all(np.isfinite(vals)):
        raise ParameterError("adjacency weights must be finite", block=block,
                             param="adjacency")
    order = np.lexsort((cols, rows))
    rows, cols, vals = rows[order], cols[order], vals[order]
    deg = np.bincount(rows, minlength=n)
    k = max(int(deg.max(initial=0)), 1)
    start = np.concatenate([[0], np.cumsum(deg)[:-1]])
    slot = np.arange(len(rows)) - start[rows]
    idx = np.full((n, k), -1, dtype=np.int64)
    w = np.zeros((n, k))
    idx[rows, slot] = cols
    w[rows, slot] = vals
    return idx, w


def laplacian(adjacency):
    """Graph Laplacian ``L = D - A`` of a dense (N, N) adjacency matrix."""
    a = np.asarray(adjacency, dtype=float)
    a = a - np.diag(np.diag(a))
    return np.diag(a.sum(axis=1)) - a


class NeighborSource:
    """Declares and resolves the neighbour set of a swarm controller block.

    Call :meth:`declare` from the block's ``__init__`` and :meth:`get` from
    ``output()``; :meth:`configure` from the block's ``configure``.
    """

    def __init__(self, block, n, *, adjacency=None, radius=None, k_max=None,
                 position_port="position", radius_param="radius"):
        name = type(block).__name__
        self.block = name
        self._owner = block
        self.radius_param = radius_param
        self.n = n
        self.position_port = position_port
        self.fixed = None
        if adjacency is not None and radius is not None:
            raise ParameterError("give either adjacency or radius, not both",
                                 block=name, param="adjacency")
        if adjacency is not None:
            self.mode = "fixed"
            self.fixed = adjacency_to_neighbors(adjacency, n, name)
        elif radius is not None:
            self.mode = "radius"
            # a numeric parameter of the owning block ("block.radius")
            if radius_param not in block.parameters:
                block.declare_parameter(radius_param,
                                        positive_scalar(radius, name, radius_param,
                                                        allow_inf=True),
                                        bounds=(1e-12, None), allow_inf=True, unit="m")
            if k_max is None:
                raise ParameterError("k_max is needed with radius", block=name,
                                     param="k_max")
            self.k_max = int(k_max)
            if self.k_max < 1:
                raise ParameterError("k_max must be >= 1", block=name,
                                     param="k_max", found=k_max)
            spec = block._inputs.get(position_port)
            dim = spec.shape[1] if spec is not None and spec.shape is not None and \
                len(spec.shape) == 2 else 2
            self.search = None
            if dim in (2, 3):
                self.search = NeighborSearch(float(getattr(block, radius_param)),
                                             points=position_port, dim=dim)
                block._neighbor_search = self.search
        else:
            self.mode = "port"
            block.declare_input("neighbors", None, "int64",
                                doc="(N, K) neighbour indices, -1 padded")

    def configure(self, inputs):
        if self.mode != "port":
            return
        sp = inputs.get("neighbors")
        if sp is None:
            return
        if sp.shape is None or len(sp.shape) != 2 or sp.shape[0] != self.n:
            raise ShapeError("neighbors must be (N, K)", block=self.block,
                             port="neighbors", expected=f"({self.n}, K)",
                             found=sp.shape)
        if not np.issubdtype(np.dtype(sp.dtype), np.integer):
            raise ShapeError("neighbors must be integer indices", block=self.block,
                             port="neighbors", expected="int64", found=sp.dtype)

    def indices(self, u, pos, xp):
        """(N, K) neighbour indices, -1 padded (no weights: for laws that
        weigh neighbours themselves)."""
        if self.mode == "fixed":
            return xp.asarray(self.fixed[0])
        if self.mode == "radius":
            r = getattr(self._owner, self.radius_param)
            if self.search is None:                 # 1-D positions: NumPy only
                idx, _ = radius_neighbors(np.asarray(pos), float(r), self.k_max)
            else:
                idx, _ = self.search.nearest(pos, r, self.k_max, xp=xp)
            return idx
        return u["neighbors"]

    def get(self, u, pos, xp):
        """``(idx, w)``: (N, K) indices (-1 padded) and weights (1 or from A)."""
        if self.mode == "fixed":
            idx, w = self.fixed
            return xp.asarray(idx), xp.asarray(w)
        idx = self.indices(u, pos, xp)
        return idx, xp.where(idx >= 0, 1.0, 0.0)


def gather(x, idx, xp):
    """``x[idx]`` with padded entries (-1) replaced by the agent's own row.

    Returns ``(xj, mask)``: (N, K, ...) neighbour values and (N, K) bool.
    """
    mask = idx >= 0
    n = x.shape[0]
    own = xp.arange(n)[:, None]
    safe = xp.where(mask, idx, own)
    if xp is np:                     # the same rows; np.take is ~10x faster
        return np.take(x, safe, axis=0), mask
    return x[safe], mask
