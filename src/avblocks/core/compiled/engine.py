"""The diagram's semantics written for tracing: one major step as pure JAX.

:class:`TracedEngine` evaluates a :class:`~avblocks.core.diagram.CompiledDiagram`
with ``xp = jax.numpy`` and implements the engine interface the fixed-step
solvers use (``derivs``, ``minor_outputs``, ``axpy``, ``combine``; see
:mod:`avblocks.core.solvers`), so one solver object serves both backends.
It follows the major step written out in :mod:`avblocks.core.simulator`:

    X <- discrete updates at t_k (periodic blocks only at their hits)
    X <- solver step from t_k to t_k+1 (outputs of continuous blocks that feed
         continuous states recomputed at each stage; periodic blocks hold)
    Y <- outputs at t_k+1 (periodic blocks only at their hits, else held)

Every call of a block's function is wrapped: an exception raised while
tracing (NumPy/SciPy code on a traced value, Python control flow on a traced
value...) becomes a :class:`~avblocks.core.errors.CompileError` naming the
block and suggesting ``backend="numpy"``.
"""

from __future__ import annotations

import numpy as np

from ..block import Periodic
from ..engine import Engine as _Engine
from ..errors import AvError, CompileError, ShapeError


def _select(hit, new, old, xp):
    if hit is True:
        return new
    return {k: xp.where(hit, new[k], old[k]) for k in old}


class TracedEngine:
    """Pure, traceable evaluation of a compiled diagram (see module doc)."""

    def __init__(self, compiled, dt, xp, canon=np.dtype):
        self.cd = compiled
        self.canon = canon          # declared dtype -> dtype of this trace (x64 or not)
        self.xp = xp
        self.dt = float(dt)
        self.blocks = compiled.blocks
        self.names = compiled.names
        self.src = [tuple((inp, s, o) for inp, (s, o) in srcs.items())
                    for srcs in compiled.sources]
        self.src_ft = [tuple(w for w in self.src[i] if w[0] in b.feedthrough)
                       for i, b in enumerate(self.blocks)]
        self.periodic = [isinstance(b.sample_time, Periodic) for b in self.blocks]
        self.with_outputs = [i for i, b in enumerate(self.blocks) if b._outputs]
        self.cont = [i for i, b in enumerate(self.blocks) if b._cstates]
        self.cont_names = {i: tuple(self.blocks[i]._cstates) for i in self.cont}
        self.disc = [i for i, b in enumerate(self.blocks) if b._dstates]
        self.per_k = [0] * len(self.blocks)
        self.off_k = [0] * len(self.blocks)
        for i, b in enumerate(self.blocks):
            if self.periodic[i]:
                st = b.sample_time
                per, off = st.period / self.dt, st.offset / self.dt
                if (abs(per - round(per)) > 1e-6 * max(per, 1)
                        or abs(off - round(off)) > 1e-6 * max(per, 1) or round(per) < 1):
                    raise ShapeError(
                        f"sample period {st.period} / offset {st.offset} is not a "
                        f"multiple of the major step dt={self.dt}", block=self.names[i],
                        hint="choose dt so that every discrete period is a whole "
                             "number of steps")
                self.per_k[i], self.off_k[i] = int(round(per)), int(round(off))
        # outputs needed inside solver stages: feedthrough ancestors of the
        # inputs of continuous blocks (others would be dead code anyway)
        need, stack = set(), [s for i in self.cont for (_inp, s, _o) in self.src[i]]
        while stack:
            j = stack.pop()
            if j in need:
                continue
            need.add(j)
            stack += [s for (inp, s, _o) in self.src[j] if inp in self.blocks[j].feedthrough]
        self.minor = [i for i in self.with_outputs if i in need and not self.periodic[i]]

    # --------------------------------------------------------------- calls
    def _call(self, i, what, fn, *args, **kw):
        try:
            return fn(*args, **kw)
        except AvError:
            raise
        except Exception as e:  # noqa: BLE001 - name the block that failed
            raise CompileError(
                f"{what}() cannot be traced by JAX: {type(e).__name__}: "
                f"{str(e).splitlines()[0] if str(e) else ''}",
                block=self.names[i],
                hint="run this diagram with backend='numpy', or write the block's "
                     "math with the array namespace `xp` it is handed (no NumPy/SciPy "
                     "calls or Python `if` on its inputs, states or parameters)") from e

    def hits(self, k):
        out = [None] * len(self.blocks)
        for i, p in enumerate(self.periodic):
            if p:
                off, per = self.off_k[i], self.per_k[i]
                out[i] = (k >= off) & ((k - off) % per == 0)
        return out

    def gather(self, i, Y):
        return {inp: Y[s][o] for inp, s, o in self.src[i]}

    def _out(self, i, t, X, Y):
        b = self.blocks[i]
        u = {inp: Y[s][o] for inp, s, o in self.src_ft[i]}
        y = self._call(i, "output", b.output, t, X[i], u, self.xp)
        if not isinstance(y, dict):
            if len(b._outputs) != 1:
                raise CompileError("output() must return a dict {port: array} for a "
                                   "block with several outputs", block=self.names[i],
                                   found=type(y).__name__)
            y = {next(iter(b._outputs)): y}
        out = {}
        for o, p in b._outputs.items():
            if o not in y:
                raise ShapeError("output() did not return this port", block=self.names[i],
                                 port=o, expected=sorted(b._outputs), found=sorted(y))
            a = self.xp.asarray(y[o])
            if tuple(a.shape) != tuple(p.shape):
                raise ShapeError("output() returned the wrong shape", block=self.names[i],
                                 port=o, expected=p.shape, found=tuple(a.shape))
            if np.dtype(a.dtype).kind != np.dtype(p.dtype).kind:
                raise ShapeError("output() returned the wrong dtype", block=self.names[i],
                                 port=o, expected=p.dtype, found=np.dtype(a.dtype).name)
            # a fixed dtype per port keeps the scan's carry type stable
            out[o] = self.xp.asarray(a, dtype=self.canon(p.dtype))
        return out

    # output sweeps are the NumPy engine's: they call this class's _out, and
    # its _select takes a traced hit flag as well as a Python bool
    all_outputs = _Engine.all_outputs
    major_outputs = _Engine.major_outputs
    minor_outputs = _Engine.minor_outputs

    def update(self, t, X, Y, hits):
        X = list(X)
        for i in self.disc:
            b = self.blocks[i]
            if b.update_uses_outputs:
                new = self._call(i, "update", b.update, t, X[i], self.gather(i, Y),
                                 self.xp, y=Y[i])
            else:
                new = self._call(i, "update", b.update, t, X[i], self.gather(i, Y), self.xp)
            merged = {**X[i], **new}
            # keep the declared dtypes (a block may return e.g. int32 from a where)
            merged = {k: self.xp.asarray(v, dtype=X[i][k].dtype) for k, v in merged.items()
                      if k in X[i]}
            X[i] = _select(hits[i] if self.periodic[i] else True, merged, X[i], self.xp)
        return X

    def derivs(self, t, X, Y):
        return [self._call(i, "derivative", self.blocks[i].derivative, t, X[i],
                           self.gather(i, Y), self.xp) for i in self.cont]

    # the solver's state arithmetic is the NumPy engine's, unchanged
    axpy = _Engine.axpy
    combine = _Engine.combine
