"""What a traced run must check after it ends (static-capacity overflows).

Blocks whose shapes are fixed by a plan (a neighbour search's cell capacity
and reach, see :mod:`avblocks.utility.spatial`) hand what each evaluation
*needed* to :func:`report`. While the compiled engine traces a run it
collects these values (running maxima carried through the scan) and checks
them against the plan when the run ends; outside a trace :func:`report` does
nothing (NumPy searches size themselves).

This first version only defines the block-facing call; the compiled
engine's collector is added with the overflow handling.
"""

from __future__ import annotations

import contextvars

_ACTIVE: contextvars.ContextVar = contextvars.ContextVar("avblocks_diag", default=None)


def report(owner, need, plan):
    """Record that ``owner`` (a search object) needed ``need`` under ``plan``."""
    col = _ACTIVE.get()
    if col is not None:
        col.add(owner, need, plan)
