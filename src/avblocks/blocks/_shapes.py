"""Shape helpers shared by the shape-polymorphic blocks (private)."""

from __future__ import annotations

import numpy as np

from ..core.errors import ShapeError
from ..core.params import finite_array
from ..core.ports import Port


def bounds(value, block, name):
    """A float array for a bound: NaN refused, +-inf allowed (one-sided)."""
    return finite_array(value, block, name, allow_inf=True)


def broadcast_to_input(param, inp: Port, block, pname, port="u"):
    """Check that parameter array ``param`` broadcasts to the shape of the
    signal ``inp`` wired to input ``port`` (``inp.name`` is the driver's)."""
    try:
        out = np.broadcast_shapes(inp.shape, np.shape(param))
    except ValueError:
        out = None
    if out != tuple(inp.shape):
        raise ShapeError(f"parameter '{pname}' does not broadcast to the input",
                         block=block, port=port, expected=f"a signal that {pname} "
                         f"of shape {np.shape(param)} broadcasts to", found=inp.shape)


def set_output(block, name, shape, dtype, agents=None):
    """Re-declare output ``name`` with a concrete shape (and agent flag)."""
    block.redeclare_output(name, shape, dtype)
    if agents is not None and block._outputs[name].agents != agents:
        p = block._outputs[name]
        block._outputs[name] = Port(p.name, p.shape, p.dtype, p.unit, p.labels,
                                    p.doc, agents)


def set_discrete_state(block, name, value, *, dtype=None, agents=True):
    """Declare a discrete state from ``configure`` (idempotent across builds).

    The core has no ``redeclare_discrete_state``; a block reconfigured by a
    second build re-declares the state with the (possibly new) shape here.
    """
    if name in block._dstates:
        del block._dstates[name]
        del block._init[name]
    block.declare_discrete_state(name, value, dtype=dtype, agents=agents)
