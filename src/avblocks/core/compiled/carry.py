"""The step loop's carry packed into few buffers: one kernel per step.

XLA on CPU runs a ``lax.scan`` step as a sequence of kernels (one per fused
loop, plus a copy of each carried buffer it cannot update in place), and at
small N their fixed cost is most of a step. A carry of several arrays
becomes several fused loops, each recomputing what they share (the W1 step,
a pose and an arrival latch: the heading's sin/cos in both). Concatenated
into one array the new carry is one fused loop and one copy: W1 at N = 10
ran its hand-written scan in 0.68 ms instead of 0.87 ms (benchmarks/
scaling.py --percall; docs/benchmarks.md).

:class:`Packing` groups the carry's leaves by their leading length (the
agent axis, usually), flattens each to ``(L, columns)`` and concatenates
the leaves of a group along the columns, in the trace's float dtype. Only
conversions that round-trip exactly are used (booleans as 0/1, narrower
floats and integers with fewer bits than the mantissa), so unpacking gives
back the same values bit for bit; other leaves (64-bit integers, complex
numbers) and groups of one leaf stay as they are.

Packing pays where the step is short elementwise work on the agents
(vehicles, controllers, sources under Euler): XLA fuses the whole step into
one loop. A step that also sorts, scatters, reduces or loops (a neighbour
search, a switch time's split, a rigid body's rotation products) reads the
state in kernels of their own, each of which would read its slice of the
packed buffer through one more kernel (the flocking step, 300 agents: 108
kernels instead of 95); and a long step (RK4's four stages, random draws)
costs more recomputed in one loop than the kernels it saves.
:func:`scan_steps` traces the step once, looks at what it does
(:func:`worth_packing`) and packs only where it pays.
"""

from __future__ import annotations

import math

import numpy as np

from . import _jax


def _packable(dtype, into):
    """Whether ``dtype`` converts to the float dtype ``into`` and back exactly."""
    dtype, into = np.dtype(dtype), np.dtype(into)
    if dtype == into or dtype.kind == "b":
        return True
    if dtype.kind == "f":
        return dtype.itemsize <= into.itemsize
    if dtype.kind in "iu":
        return dtype.itemsize * 8 < np.finfo(into).nmant + 1
    return False


# operations that XLA runs as kernels of their own, or that end a fused loop
# (reductions, products): a step with any of them is several kernels anyway
_OWN_KERNEL = ("sort", "scatter", "while", "scan", "cum", "reduce_", "argm", "dot_general",
               "select_and_", "fft", "conv_general", "ffi_call", "pure_callback",
               "io_callback", "top_k", "cholesky", "lu", "qr", "eig", "svd",
               "triangular_solve")
# operations that only move or relabel values (not counted as work)
_LAYOUT = frozenset(("slice", "squeeze", "reshape", "broadcast_in_dim", "expand_dims",
                     "concatenate", "transpose", "convert_element_type", "jit", "pjit",
                     "copy", "copy_p"))
#: the longest step (operations, layout ones not counted) that is packed
MAX_PACKED_OPS = 100


def _work(jaxpr):
    """Operations of a traced step (nested calls and branches included), or
    None if one of them is a kernel of its own (see ``_OWN_KERNEL``)."""
    from jax.extend.core import subjaxprs
    n = 0
    for e in jaxpr.eqns:
        name = e.primitive.name
        if name.startswith(_OWN_KERNEL) and name != "reduce_precision":
            return None
        n += name not in _LAYOUT
    for sub in subjaxprs(jaxpr):
        m = _work(sub)
        if m is None:
            return None
        n += m
    return n


def worth_packing(jaxpr) -> bool:
    """Whether the step loop should carry its state packed: the traced step
    is elementwise work (gathers included) that XLA fuses into one loop,
    and short. That loop computes each column of the packed state from the
    step's inputs, recomputing what the columns share, which costs more
    than the kernels it saves once the step is long (measured at N = 10,
    Euler, us per step unpacked -> packed: W1 (45 operations) 0.36 -> 0.26,
    waypoints (56) 0.6 -> 0.5, a multirate chain (56) 0.8 -> 0.6; with RK4
    (119-209 operations) 1.2-1.4 -> 1.5-1.6; random walks (545) at N = 100
    6 -> 15)."""
    n = _work(jaxpr)
    return n is not None and n <= MAX_PACKED_OPS


def scan_steps(step, carry, ks, fdtype):
    """``lax.scan`` of ``step(carry, k) -> carry`` over ``ks``, with the
    carry packed when :func:`worth_packing`; returns the last carry. The
    step is traced once (its jaxpr is the loop body)."""
    jax = _jax.jax()
    from jax.extend.core import jaxpr_as_fun
    closed, shape = jax.make_jaxpr(step, return_shape=True)(carry, ks[0])
    body = jaxpr_as_fun(closed)
    treedef = jax.tree_util.tree_structure(shape)
    pk = Packing(carry, fdtype if worth_packing(closed.jaxpr) else None)

    def loop(c, k):
        return pk.pack(body(*pk.unpack_flat(c), k)), None

    last, _ = jax.lax.scan(loop, pk.pack(jax.tree_util.tree_leaves(carry)), ks)
    return jax.tree_util.tree_unflatten(treedef, pk.unpack_flat(last))


class Packing:
    """Layout of the leaves of one carry (fixed at trace time) in float
    buffers of dtype ``fdtype`` (None: nothing packed): ``pack(leaves)``
    gives ``(buffers, others)``, ``unpack_flat`` the leaves back, values
    unchanged."""

    def __init__(self, tree, fdtype):
        jax = _jax.jax()
        leaves = jax.tree_util.tree_leaves(tree)
        self.fdtype = None if fdtype is None else np.dtype(fdtype)
        self.meta = [(tuple(a.shape), np.dtype(a.dtype)) for a in leaves]
        groups: dict = {}
        for j, (shape, dt) in enumerate(self.meta):
            if fdtype is not None and _packable(dt, self.fdtype) and math.prod(shape) > 0:
                groups.setdefault(shape[0] if shape else 1, []).append(j)
        #: [(leading length, [leaf indices])] of the packed buffers
        self.groups = [(n, js) for n, js in groups.items() if len(js) > 1]
        packed = {j for _, js in self.groups for j in js}
        self.others = [j for j in range(len(leaves)) if j not in packed]

    def pack(self, leaves):
        jnp = _jax.jax().numpy
        bufs = tuple(jnp.concatenate([jnp.reshape(leaves[j], (n, -1)).astype(self.fdtype)
                                      for j in js], axis=1) for n, js in self.groups)
        return bufs, [leaves[j] for j in self.others]

    def unpack_flat(self, packed):
        jnp = _jax.jax().numpy
        bufs, others = packed
        leaves = [None] * len(self.meta)
        for (_, js), buf in zip(self.groups, bufs):
            col = 0
            for j in js:
                shape, dt = self.meta[j]
                width = math.prod(shape[1:]) if shape else 1
                a = jnp.reshape(buf[:, col:col + width], shape)
                col += width
                if dt.kind == "b":
                    a = a != 0
                elif dt != self.fdtype:
                    a = a.astype(dt)
                leaves[j] = a
        for j, a in zip(self.others, others):
            leaves[j] = a
        return leaves
