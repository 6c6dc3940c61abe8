"""The pure part of the simulator: evaluate outputs, derivatives and updates
of a compiled diagram for given states. Shared by the NumPy loop and by the
JAX trace, so both run exactly the same semantics.

``X`` is a list (one entry per block, in evaluation order) of dicts of state
arrays; ``Y`` a list of dicts of output arrays. Nothing here mutates its
arguments: each function returns new lists.
"""

from __future__ import annotations

import math

import numpy as np

from .block import Periodic
from .errors import ShapeError, SimulationError


def select(hit, new, old, xp):
    """``new`` where ``hit`` else ``old`` (dicts of arrays); Python or traced."""
    if hit is True:
        return new
    if hit is False:
        return old
    return {k: xp.where(hit, new[k], old[k]) for k in old}


class Engine:
    """Pure evaluation of a :class:`CompiledDiagram` with array namespace ``xp``."""

    def __init__(self, compiled, dt, xp=np):
        self.cd = compiled
        self.xp = xp
        self.dt = float(dt)
        self.blocks = compiled.blocks
        self.names = compiled.names
        nb = len(self.blocks)
        self.src = [tuple((inp, s, o) for inp, (s, o) in srcs.items())
                    for srcs in compiled.sources]
        self.src_ft = [tuple((inp, s, o) for inp, s, o in self.src[i]
                             if inp in b.feedthrough) for i, b in enumerate(self.blocks)]
        self.periodic = [isinstance(b.sample_time, Periodic) for b in self.blocks]
        self.single_out = [next(iter(b._outputs)) if len(b._outputs) == 1 else None
                           for b in self.blocks]
        self.with_outputs = [i for i, b in enumerate(self.blocks) if b._outputs]
        self.cont = [i for i, b in enumerate(self.blocks) if b._cstates]
        self.cont_names = {i: tuple(self.blocks[i]._cstates) for i in self.cont}
        self.disc = [i for i, b in enumerate(self.blocks) if b._dstates]
        self.any_periodic = any(self.periodic)
        self._no_hits = [None] * nb
        # sample hits on the major-step grid
        self.per_k = [0] * nb
        self.off_k = [0] * nb
        for i, b in enumerate(self.blocks):
            if self.periodic[i]:
                st = b.sample_time
                per, off = st.period / self.dt, st.offset / self.dt
                if (abs(per - round(per)) > 1e-6 * max(per, 1)
                        or abs(off - round(off)) > 1e-6 * max(per, 1) or round(per) < 1):
                    raise ShapeError(
                        f"sample period {st.period} / offset {st.offset} is not a "
                        f"multiple of the major step dt={self.dt}",
                        block=self.names[i],
                        hint="choose dt so that every discrete period is a whole "
                             "number of steps (e.g. dt = gcd of the periods)")
                self.per_k[i] = int(round(per))
                self.off_k[i] = int(round(off))
        # blocks whose outputs matter inside solver stages: ancestors (through
        # feedthrough wires) of the inputs of continuous blocks.
        need = set()
        stack = [s for i in self.cont for (_inp, s, _o) in self.src[i]]
        while stack:
            j = stack.pop()
            if j in need:
                continue
            need.add(j)
            ft = self.blocks[j].feedthrough
            stack += [s for (inp, s, _o) in self.src[j] if inp in ft]
        self.minor = [i for i in self.with_outputs if i in need and not self.periodic[i]]
        # continuous state layout for packing into one vector (scipy)
        self.layout = []
        off = 0
        for i in self.cont:
            for nm in self.cont_names[i]:
                shape = self.blocks[i]._cstates[nm].shape
                size = int(math.prod(shape))
                self.layout.append((i, nm, shape, off, off + size))
                off += size
        self.size = off
        self._kpos = {i: j for j, i in enumerate(self.cont)}

    def feedthrough_ancestors(self, blocks):
        """The indices of ``blocks`` and of every block upstream of them
        through direct-feedthrough wires: what their outputs at one time
        read at that time (a block without feedthrough gives its output
        from its state alone)."""
        seen, stack = set(), list(blocks)
        while stack:
            j = stack.pop()
            if j not in seen:
                seen.add(j)
                stack += [k for _inp, k, _o in self.src_ft[j]]
        return seen

    # ----------------------------------------------------------------- pieces
    def hits(self, k):
        """Per-block sample-hit flags at major step ``k`` (None if continuous)."""
        if not self.any_periodic:
            return self._no_hits
        traced = not isinstance(k, (int, np.integer))
        out = [None] * len(self.blocks)
        for i, p in enumerate(self.periodic):
            if p:
                off, per = self.off_k[i], self.per_k[i]
                if traced:
                    out[i] = (k >= off) & ((k - off) % per == 0)
                else:
                    out[i] = bool(k >= off and (k - off) % per == 0)
        return out

    def gather(self, i, Y):
        return {inp: Y[s][o] for inp, s, o in self.src[i]}

    def _out(self, i, t, X, Y):
        # output() sees only its direct-feedthrough inputs: the others may not
        # be computed yet at this point of the sorted evaluation.
        u = {inp: Y[s][o] for inp, s, o in self.src_ft[i]}
        y = self.blocks[i].output(t, X[i], u, self.xp)
        if not isinstance(y, dict):
            name = self.single_out[i]
            if name is None:
                raise SimulationError(
                    "output() must return a dict {port: array} for a block with "
                    "several outputs", block=self.names[i], time=t,
                    found=type(y).__name__)
            y = {name: y}
        return y

    def major_outputs(self, t, X, Yprev, hits):
        """Outputs at a major step: periodic blocks only at their hits."""
        Y = list(Yprev)
        xp = self.xp
        for i in self.with_outputs:
            if self.periodic[i]:
                h = hits[i]
                if h is False:
                    continue
                Y[i] = select(h, self._out(i, t, X, Y), Yprev[i], xp)
            else:
                Y[i] = self._out(i, t, X, Y)
        return Y

    def all_outputs(self, t, X, Y):
        """Every block's outputs, periodic ones included (initial outputs)."""
        Y = list(Y)
        for i in self.with_outputs:
            Y[i] = self._out(i, t, X, Y)
        return Y

    def minor_outputs(self, t, X, Y):
        """Outputs inside solver stages: only what feeds continuous states."""
        Y = list(Y)
        for i in self.minor:
            Y[i] = self._out(i, t, X, Y)
        return Y

    def update(self, t, X, Y, hits):
        """Discrete updates at a major step (every step for continuous blocks,
        at hits for periodic ones)."""
        X = list(X)
        xp = self.xp
        for i in self.disc:
            h = hits[i] if self.periodic[i] else True
            if h is False:
                continue
            b = self.blocks[i]
            if b.update_uses_outputs:
                new = b.update(t, X[i], self.gather(i, Y), xp, y=Y[i])
            else:
                new = b.update(t, X[i], self.gather(i, Y), xp)
            merged = {**X[i], **new}
            X[i] = select(h, merged, X[i], xp)
        return X

    def derivs(self, t, X, Y):
        return [self.blocks[i].derivative(t, X[i], self.gather(i, Y), self.xp)
                for i in self.cont]

    def axpy(self, X, a, K):
        X = list(X)
        for i, k in zip(self.cont, K):
            xi = X[i]
            X[i] = {**xi, **{nm: xi[nm] + a * k[nm] for nm in self.cont_names[i]}}
        return X

    def combine(self, X, terms):
        X = list(X)
        for j, i in enumerate(self.cont):
            xi = X[i]
            upd = {}
            for nm in self.cont_names[i]:
                acc = xi[nm]
                for a, K in terms:
                    acc = acc + a * K[j][nm]
                upd[nm] = acc
            X[i] = {**xi, **upd}
        return X

    # ------------------------------------------------------- flat vectors
    def pack(self, X):
        if not self.layout:
            return np.zeros(0)
        return np.concatenate([np.ravel(X[i][nm]) for i, nm, *_ in self.layout])

    def pack_derivs(self, K):
        pos = self._kpos
        return np.concatenate([np.ravel(K[pos[i]][nm]) for i, nm, *_ in self.layout])

    def unpack(self, y, X):
        X = list(X)
        for i, nm, shape, a, b in self.layout:
            X[i] = {**X[i], nm: np.reshape(y[a:b], shape)}
        return X
