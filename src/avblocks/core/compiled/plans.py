"""Static plans of the neighbour searches blocks own, and overflow handling.

A traced search has static shapes (see :mod:`avblocks.utility.spatial`):
its candidate capacity and hit width are fixed before tracing. The compiled
engine (:func:`avblocks.compile`):

1. **plans** every search a block owns (``block.searches()``, or each
   attribute that is a ``NeighborSearch``; see
   :func:`avblocks.core.diagnostics.searches_of`) from the block's input
   values at ``t0`` the first time the block is compiled (or, when the
   search's ``points`` names a parameter such as fixed targets, from that
   parameter's value), computed by the NumPy engine (one initial
   evaluation, no step), unless the user fixed
   ``capacity=``. The plan is part of the block's structure, so it is part
   of the compile-cache key; it is kept for the block's life and only grows
   (after an overflow, step 3), so a grown plan is not planned away again;
2. during the run, each search call adds what it needed to a running
   maximum the run carries and returns (:mod:`avblocks.core.diagnostics`;
   nothing is called back to the host);
3. after the run, where a search needed more than its plan:

   - ``on_overflow="replan"`` (default): a :class:`RuntimeWarning` names
     the block and the sizes, the search is re-planned with the needed size
     times its ``headroom``, the program is compiled again and the run
     repeated. A run may be re-planned :data:`REPLANS` (2) times: the hits
     counted behind an overflowed capacity are an estimate. A run that
     overflows after that raises;
   - ``on_overflow="raise"``: :class:`~avblocks.core.errors.SimulationError`
     naming the block, "capacity" (or "hits", "radius"), needed vs planned.

An ensemble's need is the largest over its runs.

A block whose state shapes follow its plans (the Verlet list of
``environment.Neighbors``) defines ``searches_planned()``; it is called after
every planning and growing, before the program is built.
"""

from __future__ import annotations

import warnings
from types import SimpleNamespace

import numpy as np

from .. import diagnostics
from ..errors import ParameterError, SimulationError

MODES = ("replan", "raise")

#: Re-planning rounds one run may take before an overflow raises (a grown
#: capacity lets more hits through than were counted: a second round)
REPLANS = 2


def check_mode(mode):
    if mode not in MODES:
        raise ParameterError("unknown on_overflow", param="on_overflow",
                             expected=" or ".join(repr(m) for m in MODES), found=mode)
    return mode


def owned(cd):
    """``[(block index, search number, search)]`` of a compiled diagram."""
    out = []
    for i, b in enumerate(cd.blocks):
        for j, s in enumerate(diagnostics.searches_of(b)):
            out.append((i, j, s))
    return out


def plan_searches(cd, *, dt, t0=0.0, seed=0, x0=None):
    """Plan every search of ``cd`` not fixed by its user, from the NumPy
    engine's block inputs at ``t0``. Returns the number planned."""
    # a search planned before keeps its plan: a run that outgrows it is caught
    # after the run and re-planned (step 3), so a second compile of the same
    # blocks (every ``simulate(backend="jax")`` call) needs no NumPy evaluation
    todo = [(i, s) for i, _, s in owned(cd)
            if not getattr(s, "fixed", False) and getattr(s, "cells", None) is None]
    if not todo:
        _planned(cd)
        return 0
    from ..simulator import Simulator
    sim = Simulator(cd, dt, "euler", seed=seed, t0=t0, x0=x0, check_finite=False)
    sim.init()
    for i, s in todo:
        u = sim.eng.gather(i, sim.Y)
        params = getattr(cd.blocks[i], "_params", {})
        if s.points in u:                       # an input: its value at t0
            pts = u[s.points]
        elif s.points in params:                # a parameter (e.g. fixed targets)
            pts = cd.blocks[i].get_parameter(s.points)
        else:
            raise ParameterError("a neighbour search names neither an input nor a "
                                 "parameter of its block", block=cd.names[i],
                                 param="points", expected=sorted(u) + sorted(params),
                                 found=s.points)
        s.plan(np.asarray(pts))
    _planned(cd)
    return len(todo)


def _planned(cd):
    """Tell the blocks that own searches their plans are set (or grew): a
    block whose state shapes follow a plan (``Neighbors``' Verlet list)
    re-declares them in its ``searches_planned()``."""
    for b in cd.blocks:
        hook = getattr(b, "searches_planned", None)
        if callable(hook):
            hook()


def overflows(cd, needs):
    """``[(block name, search, need, message)]`` of the searches whose need
    exceeds their plan; ``needs`` is ``{(block name, search number):
    [capacity, hits, reach, span]}`` (a run's tally, see
    :meth:`~avblocks.core.compiled.program.Program.needs`)."""
    out = []
    if not needs:
        return out
    for i, j, s in owned(cd):
        v = needs.get((cd.names[i], j))
        if v is None or s.cells is None:
            continue
        need = SimpleNamespace(capacity=int(v[0]), reach=float(v[2]), hits=int(v[1]),
                               span=float(v[3]))
        msg = s.cells.exceeded(need)
        if msg:
            out.append((cd.names[i], s, need, msg))
    return out


def settle(runner, over, rerun):
    """Act on ``over`` (from :func:`overflows`) after a run of ``runner``:
    raise, or grow the plans, rebuild the runner's program and return
    ``rerun()``'s result."""
    names = ", ".join(f"'{n}' ({m})" for n, _, _, m in over)
    mode = getattr(runner, "on_overflow", "replan")
    bad_reach = [n for n, s, need, _ in over
                 if float(need.reach) > s.cells.reach * (1 + 1e-6) or need.span > 1.0]
    rounds = getattr(runner, "_replanned", 0)
    if mode == "raise" or bad_reach or rounds >= REPLANS:
        why = "a compiled neighbour search overflowed its static plan"
        if rounds:
            why += " again after re-planning"
        raise SimulationError(f"{why}: {names}", block=over[0][0],
                              hint="give the block a larger capacity=, or compile with "
                                   "on_overflow='replan' (the default)")
    for _, s, need, _ in over:
        s.cells = s.cells.grown(need, s.headroom)
    _planned(runner.compiled)
    warnings.warn(f"compiled run re-planned after a neighbour search overflow: {names}; "
                  "compiling again and repeating the run", RuntimeWarning, stacklevel=3)
    runner._rebuild_program()
    runner._replanned = rounds + 1
    try:
        return rerun()
    finally:
        runner._replanned = rounds
