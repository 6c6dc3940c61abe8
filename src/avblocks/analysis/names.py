"""Names of the entries of a linear model: states, inputs and outputs by
block, port (or state), agent and component.

An array of shape ``(N, k)`` declared per agent (``agents=True``) with
component labels ``("x", "y", "theta")`` is flattened row by row (NumPy's
C order, the order the engines pack states in) and its entries are named
``"fleet.pose[0].x"``, ``"fleet.pose[0].y"``, ... ``"fleet.pose[N-1].theta"``:
block path, port or state name, agent index in brackets, component label.
Without labels the component is an index (``"law.velocity[3][1]"``); an array
that is not per agent has no agent index (``"drive.gain[1]"``), a scalar is
just ``"block.name"``.

>>> from avblocks.core.ports import Port
>>> entry_names("fleet.pose", Port("pose", (2, 3), labels=("x", "y", "theta")))[:4]
['fleet.pose[0].x', 'fleet.pose[0].y', 'fleet.pose[0].theta', 'fleet.pose[1].x']
"""

from __future__ import annotations

import itertools


def entry_names(path: str, spec) -> list[str]:
    """Names of the entries of the array ``spec`` (a Port of a state or a
    signal) of ``path`` (``"block.name"``), in C order."""
    shape = tuple(spec.shape or ())
    if not shape:
        return [path]
    labels = tuple(spec.labels or ())
    last_labelled = bool(labels) and len(labels) == shape[-1]
    agents = bool(getattr(spec, "agents", False))
    names = []
    for idx in itertools.product(*(range(s) for s in shape)):
        text = path
        for axis, j in enumerate(idx):
            if axis == len(shape) - 1 and last_labelled and not (agents and axis == 0):
                text += f".{labels[j]}"
            else:
                text += f"[{j}]"
        names.append(text)
    return names
