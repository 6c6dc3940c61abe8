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

from .. import diagnostics as _diagnostics
from ..engine import Engine as _Engine
from ..engine import select
from ..errors import AvError, CompileError, ShapeError


class TracedEngine(_Engine):
    """Pure, traceable evaluation of a compiled diagram (see module doc).

    The diagram's structure (sources, sample-time grid, which outputs feed
    solver stages), the sample hits, the three output sweeps and the solver
    arithmetic are the NumPy :class:`~avblocks.core.engine.Engine`'s; only
    the calls into blocks differ: errors while tracing name the block, and
    outputs and updated states keep their declared dtypes (a fixed carry
    type for ``lax.scan``)."""

    def __init__(self, compiled, dt, xp, canon=np.dtype):
        super().__init__(compiled, dt, xp)
        self.canon = canon          # declared dtype -> dtype of this trace (x64 or not)

    # --------------------------------------------------------------- calls
    def _call(self, i, what, fn, *args, **kw):
        try:
            with _diagnostics.block(self.names[i], self.blocks[i]):
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
            X[i] = select(hits[i] if self.periodic[i] else True, merged, X[i], self.xp)
        return X

    def derivs(self, t, X, Y):
        return [self._call(i, "derivative", self.blocks[i].derivative, t, X[i],
                           self.gather(i, Y), self.xp) for i in self.cont]

