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


class Packing:
    """Layout of one carry pytree (fixed at trace time): ``pack(tree)`` gives
    ``(buffers, others)``, ``unpack`` the same tree back, values unchanged."""

    def __init__(self, tree, fdtype):
        jax = _jax.jax()
        leaves, self.treedef = jax.tree_util.tree_flatten(tree)
        self.fdtype = np.dtype(fdtype)
        self.meta = [(tuple(a.shape), np.dtype(a.dtype)) for a in leaves]
        groups: dict = {}
        for j, (shape, dt) in enumerate(self.meta):
            if _packable(dt, self.fdtype) and math.prod(shape) > 0:
                groups.setdefault(shape[0] if shape else 1, []).append(j)
        #: [(leading length, [leaf indices])] of the packed buffers
        self.groups = [(n, js) for n, js in groups.items() if len(js) > 1]
        packed = {j for _, js in self.groups for j in js}
        self.others = [j for j in range(len(leaves)) if j not in packed]

    def pack(self, tree):
        jax = _jax.jax()
        jnp = jax.numpy
        leaves = jax.tree_util.tree_leaves(tree)
        bufs = tuple(jnp.concatenate([jnp.reshape(leaves[j], (n, -1)).astype(self.fdtype)
                                      for j in js], axis=1) for n, js in self.groups)
        return bufs, [leaves[j] for j in self.others]

    def unpack(self, packed):
        jax = _jax.jax()
        jnp = jax.numpy
        bufs, others = packed
        leaves = [None] * len(self.meta)
        for (n, js), buf in zip(self.groups, bufs):
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
        return jax.tree_util.tree_unflatten(self.treedef, leaves)
