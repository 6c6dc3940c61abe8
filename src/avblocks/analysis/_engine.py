"""The compiled engine's traced evaluation of a diagram, with additive
perturbations at chosen input ports (the linear model's inputs).

:class:`PerturbedEngine` is the compiled engine's
:class:`~avblocks.core.compiled.engine.TracedEngine` (the very functions a
compiled run traces: outputs in evaluation order, derivatives, discrete
updates, the solver's stages) with one difference: the value a block reads
at a perturbed input port is the signal wired to it *plus* a perturbation
``delta``. Only that port sees the perturbation (another block reading the
same signal does not), as Simulink's input perturbation points do.

It does so without touching the engine's code: each perturbed port is
rewired, in this engine's own copy of the wiring tables, to a virtual
source placed after the real blocks, whose value is the real source's plus
``delta`` (:meth:`_with_virtual`).
"""

from __future__ import annotations

import numpy as np

from ..core.compiled.engine import TracedEngine


class PerturbedEngine(TracedEngine):
    """A :class:`TracedEngine` whose ``ports`` ``[(block index, input)]`` read
    their wired signal plus :attr:`delta` (a list of arrays of the ports'
    shapes, one per port; ``None``: no perturbation)."""

    def __init__(self, compiled, dt, xp, canon=np.dtype, ports=()):
        super().__init__(compiled, dt, xp, canon)
        nb = len(self.blocks)
        self.ports = list(ports)
        #: the real source (block index, output) of each perturbed port
        self.real = []
        src = [list(s) for s in self.src]
        ft = [list(s) for s in self.src_ft]
        for j, (i, inp) in enumerate(self.ports):
            s, o = compiled.sources[i][inp]
            self.real.append((s, o))
            src[i] = [(n, nb + j, "u") if n == inp else (n, s2, o2) for n, s2, o2 in src[i]]
            ft[i] = [(n, nb + j, "u") if n == inp else (n, s2, o2) for n, s2, o2 in ft[i]]
        self.src = [tuple(s) for s in src]
        self.src_ft = [tuple(s) for s in ft]
        self._all_of = [[j for j, (b, _p) in enumerate(self.ports) if b == i]
                        for i in range(nb)]
        self._ft_of = [[j for j in self._all_of[i]
                        if self.ports[j][1] in self.blocks[i].feedthrough]
                       for i in range(nb)]
        self.delta = None

    def _with_virtual(self, Y, i, feedthrough):
        """``Y`` with the virtual sources block ``i`` reads (its perturbed
        ports: only the direct-feedthrough ones for ``output``, whose other
        inputs may not be computed yet)."""
        mine = self._ft_of[i] if feedthrough else self._all_of[i]
        if not mine:
            return Y
        extra = [{} for _ in self.ports]
        for j in mine:
            s, o = self.real[j]
            v = Y[s][o]
            if self.delta is not None:
                v = v + self.delta[j]
            extra[j] = {"u": v}
        return list(Y) + extra

    def gather(self, i, Y):
        return super().gather(i, self._with_virtual(Y, i, False))

    def _out(self, i, t, X, Y):
        return super()._out(i, t, X, self._with_virtual(Y, i, True))
