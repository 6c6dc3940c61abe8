"""Routing over agents and components: select, gather, concatenate, mux, demux.

Agent axis blocks (:class:`Select`, :class:`Gather`, :class:`Concatenate`)
index or stack the leading axis; component blocks (:class:`Mux`,
:class:`Demux`) stack or split the last axis. All take their shapes from
the wiring.
"""

from __future__ import annotations

import numpy as np

from ..core.block import Block
from ..core.errors import ParameterError, ShapeError
from ._shapes import set_output


def _index_array(index, block, param):
    a = np.asarray(index)
    if a.dtype.kind == "b":
        if a.ndim != 1:
            raise ParameterError("a boolean mask must be 1-D", block=block, param=param,
                                 expected="(N,) bool", found=a.shape)
        return a
    if a.ndim != 1 or (a.size and a.dtype.kind not in "iu"):
        raise ParameterError("indices must be a 1-D sequence of integers",
                             block=block, param=param, expected="(M,) int",
                             found=f"shape {a.shape}, dtype {a.dtype}")
    return a.astype(np.int64)


def _agent_input(p, block, port="u"):
    if p.shape is None or len(p.shape) == 0:
        raise ShapeError("input has no agent axis", block=block, port=port,
                         expected="(N, ...)", found=p.shape)
    return p.shape[0]


def _resolve_index(idx, n, block, param, port):
    """Check ``idx`` against ``n`` agents; return non-negative int indices."""
    if idx.dtype.kind == "b":
        if idx.shape != (n,):
            raise ShapeError(f"mask '{param}' length differs from the agent count",
                             block=block, port=port, expected=(n,), found=idx.shape)
        return np.flatnonzero(idx)
    bad = (idx < -n) | (idx >= n)
    if np.any(bad):
        raise ShapeError(f"'{param}' has indices out of range for {n} agents",
                         block=block, port=port, expected=f"-{n} <= index < {n}",
                         found=idx[bad][:10].tolist())
    return np.where(idx < 0, idx + n, idx)


class Select(Block):
    """Pick agents by index: ``y = u[indices]``.

    Ports
    -----
    u : in, (N, ...)
    y : out, (len(indices), ...)

    Parameters
    ----------
    indices : sequence of int or boolean mask of length N
        Agents to keep, in the order given (negative indices count from the
        end, as in NumPy).

    Examples
    --------
    >>> import numpy as np, avblocks as av
    >>> d = av.Diagram()
    >>> c = d.add(av.blocks.Constant(np.arange(8.0).reshape(4, 2)), name="c")
    >>> s = d.add(Select([3, 0]), name="s")
    >>> d.connect(c.y, s.u)
    >>> av.simulate(d, 0.0, dt=0.1, log=[s.y])[s.y][0]
    array([[6., 7.],
           [0., 1.]])
    """

    #: Arguments of a small instance (the editor's palette template).
    example = {"indices": [0, 1]}

    def __init__(self, indices):
        super().__init__()
        self.declare_inherited()   # sample time of its drivers
        self._given = _index_array(indices, "Select", "indices")
        self.indices = self._given
        self.declare_input("u")
        self.declare_output("y")

    def configure(self, inputs):
        p = inputs["u"]
        n = _agent_input(p, "Select")
        self.indices = _resolve_index(self._given, n, "Select", "indices", "u")
        set_output(self, "y", (len(self.indices), *p.shape[1:]), p.dtype, True)

    def output(self, t, x, u, xp):
        return {"y": xp.take(u["u"], self.indices, axis=0)}


class Gather(Block):
    """Map each agent to another agent's signal: ``y[i] = u[index[i]]``.

    For example follower ``i`` gets the pose of its leader ``index[i]``.

    Ports
    -----
    u : in, (N, ...)
    index : in, (M,) int, only when ``index`` is None (a changing assignment)
    y : out, (M, ...)

    Parameters
    ----------
    index : sequence of int, optional
        A fixed assignment, one source agent per output agent. Leave it out
        to read the assignment from the ``index`` input port instead (it must
        hold valid indices in ``[0, N)``).
    m : int, optional
        Number of output agents with a dynamic ``index`` port (default: N).

    Examples
    --------
    >>> import numpy as np
    >>> g = Gather([0, 0, 1])
    >>> g.output(0.0, {}, {"u": np.array([[10.0], [20.0]])}, np)["y"][:, 0]
    array([10., 10., 20.])
    """

    def __init__(self, index=None, *, m=None):
        super().__init__()
        self.declare_inherited()   # sample time of its drivers
        self.dynamic = index is None
        if self.dynamic:
            self._given = None
            self.index = None
            self.m = None if m is None else int(m)
            if self.m is not None and self.m < 1:
                raise ParameterError("m must be >= 1", block="Gather", param="m",
                                     expected=">= 1", found=m)
            self.declare_input("index", None if m is None else (self.m,), "int64")
        else:
            if m is not None:
                raise ParameterError("m is only used with a dynamic index port",
                                     block="Gather", param="m", found=m)
            idx = _index_array(index, "Gather", "index")
            if idx.dtype.kind == "b":
                raise ParameterError("index must be integers, not a mask (use Select)",
                                     block="Gather", param="index")
            self._given = idx
            self.index = idx
        self.declare_input("u")
        self.declare_output("y")

    def configure(self, inputs):
        p = inputs["u"]
        n = _agent_input(p, "Gather", "u")
        if self.dynamic:
            ip = inputs["index"]
            if ip.shape is None or len(ip.shape) != 1 or np.dtype(ip.dtype).kind not in "iu":
                raise ShapeError("the index input must be a 1-D integer signal",
                                 block="Gather", port="index", expected="(M,) int",
                                 found=ip.describe())
            m = ip.shape[0]
        else:
            self.index = _resolve_index(self._given, n, "Gather", "index", "u")
            m = len(self.index)
        set_output(self, "y", (m, *p.shape[1:]), p.dtype, True)

    def output(self, t, x, u, xp):
        idx = self.index if not self.dynamic else u["index"]
        return {"y": xp.take(u["u"], idx, axis=0)}


#: most ports a routing block may declare (a port per agent is a misuse:
#: agents go along the leading axis of one port)
MAX_PORTS = 4096


def _port_names(inputs, block, param, prefix):
    if isinstance(inputs, (int, np.integer)) and not isinstance(inputs, bool):
        if not 1 <= inputs <= MAX_PORTS:
            raise ParameterError("number of ports out of range", block=block, param=param,
                                 expected=f"1 .. {MAX_PORTS}", found=inputs)
        return [f"{prefix}{j}" for j in range(int(inputs))]
    try:
        names = [str(s) for s in inputs]
    except TypeError:
        raise ParameterError("give a number of ports or a list of port names",
                             block=block, param=param, found=repr(inputs)[:80]) from None
    if not names or len(set(names)) != len(names) or not all(s.isidentifier()
                                                             for s in names):
        raise ParameterError("port names must be distinct identifiers", block=block,
                             param=param, found=names)
    return names


class Concatenate(Block):
    """Stack agent sets along the agent axis: leader + followers -> one set.

    Ports
    -----
    u0, u1, ... (or the names given) : in, (N_j, *C) with the same C
    y : out, (sum N_j, *C)

    Parameters
    ----------
    inputs : int or sequence of str
        Number of inputs (named ``u0``, ``u1``...) or their names.

    Examples
    --------
    >>> import numpy as np
    >>> c = Concatenate(["leader", "followers"])
    >>> c.output(0.0, {}, {"leader": np.zeros((1, 3)),
    ...                    "followers": np.ones((2, 3))}, np)["y"].shape
    (3, 3)
    """

    def __init__(self, inputs=2):
        super().__init__()
        self.declare_inherited()   # sample time of its drivers
        self.names = _port_names(inputs, "Concatenate", "inputs", "u")
        for nm in self.names:
            self.declare_input(nm)
        self.declare_output("y")

    def configure(self, inputs):
        ps = [inputs[nm] for nm in self.names]
        for nm, p in zip(self.names, ps):
            _agent_input(p, "Concatenate", nm)
        tails = {p.shape[1:] for p in ps}
        if len(tails) != 1:
            bad = next(nm for nm, p in zip(self.names, ps) if p.shape[1:] != ps[0].shape[1:])
            raise ShapeError("inputs differ beyond the agent axis", block="Concatenate",
                             port=bad, expected=f"(N_j, *{ps[0].shape[1:]})",
                             found={nm: p.shape for nm, p in zip(self.names, ps)})
        dtype = np.result_type(*(np.dtype(p.dtype) for p in ps))
        n = sum(p.shape[0] for p in ps)
        set_output(self, "y", (n, *ps[0].shape[1:]), dtype.name, True)

    def output(self, t, x, u, xp):
        return {"y": xp.concatenate([u[nm] for nm in self.names], axis=0)}


def _components(p):
    """(prefix shape, width, expand) of a signal seen as components on the last axis.

    A scalar or a per-agent scalar ``(N,)`` counts as one component.
    """
    s = p.shape
    if len(s) == 0 or (p.agents and len(s) == 1):
        return s, 1, True
    return s[:-1], s[-1], False


class Mux(Block):
    """Stack signals' components along the last axis.

    ``(N,)`` per-agent scalars count as one component each, so
    ``Mux(2)`` of x ``(N,)`` and y ``(N,)`` gives ``(N, 2)`` and ``Mux`` of
    a position ``(N, 2)`` and a heading ``(N,)`` gives a pose ``(N, 3)``.

    Ports
    -----
    u0, u1, ... (or the names given) : in, ``(*P, c_j)`` or ``P`` (one component)
    y : out, ``(*P, sum c_j)``

    Parameters
    ----------
    inputs : int or sequence of str
        Number of inputs (named ``u0``, ``u1``...) or their names.

    Examples
    --------
    >>> import numpy as np, avblocks as av
    >>> d = av.Diagram()
    >>> p = d.add(av.blocks.Constant([[1.0, 2.0]]), name="p")
    >>> h = d.add(av.blocks.Constant([0.5]), name="h")
    >>> m = d.add(Mux(["position", "heading"]), name="m")
    >>> d.connect(p.y, m.position); d.connect(h.y, m.heading)
    >>> av.simulate(d, 0.0, log=[m.y])[m.y][0]
    array([[1. , 2. , 0.5]])
    """

    def __init__(self, inputs=2):
        super().__init__()
        self.declare_inherited()   # sample time of its drivers
        self.names = _port_names(inputs, "Mux", "inputs", "u")
        self._expand = [False] * len(self.names)
        for nm in self.names:
            self.declare_input(nm)
        self.declare_output("y")

    def configure(self, inputs):
        ps = [inputs[nm] for nm in self.names]
        comps = [_components(p) for p in ps]
        prefixes = {c[0] for c in comps}
        if len(prefixes) != 1:
            bad = next(nm for nm, c in zip(self.names, comps) if c[0] != comps[0][0])
            raise ShapeError("inputs do not share their leading axes", block="Mux",
                             port=bad, expected=f"{(*comps[0][0], 'c')} or {comps[0][0]}",
                             found={nm: p.shape for nm, p in zip(self.names, ps)})
        self._expand = [c[2] for c in comps]
        prefix = comps[0][0]
        dtype = np.result_type(*(np.dtype(p.dtype) for p in ps))
        set_output(self, "y", (*prefix, sum(c[1] for c in comps)), dtype.name,
                   len(prefix) > 0 and any(p.agents for p in ps))

    def output(self, t, x, u, xp):
        parts = [u[nm][..., None] if e else u[nm]
                 for nm, e in zip(self.names, self._expand)]
        return {"y": xp.concatenate(parts, axis=-1)}


class Demux(Block):
    """Split a signal's last axis into several outputs.

    Ports
    -----
    u : in, ``(*P, c)``
    y0, y1, ... (or the names given) : out

    Parameters
    ----------
    sizes : int or sequence of int
        An int ``k`` splits into ``k`` single components of shape ``P`` (the
        last axis dropped: a pose ``(N, 3)`` into x, y, theta each ``(N,)``).
        A sequence gives the width of each part, each ``(*P, w_j)``: ``[2, 1]``
        splits a pose into position ``(N, 2)`` and ``(N, 1)``.
    names : sequence of str, optional
        Output names (default ``y0``, ``y1``...).

    Examples
    --------
    >>> import numpy as np
    >>> d = Demux(3, names=["x", "y", "theta"])
    >>> d.output(0.0, {}, {"u": np.array([[1.0, 2.0, 3.0]])}, np)["theta"]
    array([3.])
    """

    def __init__(self, sizes=2, names=None):
        super().__init__()
        self.declare_inherited()   # sample time of its drivers
        if isinstance(sizes, (int, np.integer)) and not isinstance(sizes, bool):
            if sizes < 1:
                raise ParameterError("need at least one output", block="Demux",
                                     param="sizes", expected=">= 1", found=sizes)
            self.widths = [1] * int(sizes)
            self.squeeze = True
        else:
            try:
                w = [int(s) for s in sizes]
            except (TypeError, ValueError):
                raise ParameterError("sizes must be an int or a sequence of ints",
                                     block="Demux", param="sizes",
                                     found=repr(sizes)[:80]) from None
            if not w or any(s < 1 for s in w):
                raise ParameterError("every width must be >= 1", block="Demux",
                                     param="sizes", expected=">= 1", found=w)
            self.widths = w
            self.squeeze = False
        self.names = _port_names(len(self.widths) if names is None else names,
                                 "Demux", "names", "y")
        if len(self.names) != len(self.widths):
            raise ParameterError("one name per output", block="Demux", param="names",
                                 expected=len(self.widths), found=len(self.names))
        self.edges = np.concatenate([[0], np.cumsum(self.widths)]).tolist()
        self.declare_input("u")
        for nm in self.names:
            self.declare_output(nm)

    def configure(self, inputs):
        p = inputs["u"]
        if len(p.shape) == 0 or p.shape[-1] != self.edges[-1]:
            raise ShapeError("the last axis does not match the sizes", block="Demux",
                             port="u", expected=f"(..., {self.edges[-1]})", found=p.shape)
        prefix = p.shape[:-1]
        for nm, w in zip(self.names, self.widths):
            shape = prefix if self.squeeze else (*prefix, w)
            set_output(self, nm, shape, p.dtype, p.agents and len(shape) > 0)

    def output(self, t, x, u, xp):
        v = u["u"]
        if self.squeeze:
            return {nm: v[..., j] for j, nm in enumerate(self.names)}
        return {nm: v[..., a:b] for nm, a, b in zip(self.names, self.edges[:-1],
                                                     self.edges[1:])}
