"""A diagram built in Python as an editor document (``av.edit(diagram)``).

Each block becomes ``{type, <argument>: <value>}`` from the arguments it was
constructed with (:func:`avblocks.core.guarded.constructor_arguments`), each
wire ``[source, destination]``. Only what a scenario file can hold is
accepted: registry block types, numbers, strings, lists and arrays (written
as lists); anything else (a Python function, a world object, a subsystem)
is refused naming the block and the argument, since the drawing could not
be saved or run as a scenario file.
"""

from __future__ import annotations

import math

from .service import EditorError


def _data(value, where):
    import numpy as np
    if isinstance(value, np.ndarray):
        if value.dtype.kind not in "biuf":
            raise EditorError(f"{where}: an array of {value.dtype} cannot be drawn",
                              kind="NotEditable")
        value = value.tolist()
    elif isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, tuple):
        value = list(value)
    if isinstance(value, list):
        return [_data(v, f"{where}[{i}]") for i, v in enumerate(value)]
    if isinstance(value, dict) and all(isinstance(k, str) for k in value):
        return {k: _data(v, f"{where}.{k}") for k, v in value.items()}
    if isinstance(value, float) and not math.isfinite(value):
        raise EditorError(f"{where}: {value} cannot be written in the document (JSON)",
                          kind="NotEditable", hint="leave the argument at its default")
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    raise EditorError(f"{where}: a {type(value).__name__} cannot be drawn (a scenario "
                      "file holds numbers, strings, lists and generators)",
                      kind="NotEditable",
                      hint="build this block from data, or draw it in the editor")


def document_of(diagram, modules=()) -> dict:
    """The editor document of ``diagram`` (a flat :class:`~avblocks.Diagram`
    of registry blocks): name, blocks with their constructor arguments,
    wires, and the new document's parameters and simulation settings."""
    from ..core.diagram import Diagram
    from ..core.guarded import constructor_arguments
    from ..scenarios.loader import block_registry
    from .service import EMPTY_DOCUMENT
    types = {cls: typ for typ, cls in block_registry(modules=modules, interfaces=True).items()}
    blocks = {}
    for name, h in diagram.blocks.items():
        b = h.block
        if isinstance(b, Diagram):
            raise EditorError(f"block '{name}' is a subsystem: a scenario file is flat",
                              kind="NotEditable")
        typ = types.get(type(b))
        if typ is None:
            raise EditorError(f"block '{name}': {type(b).__name__} is not a block a "
                              "scenario file can name", kind="NotEditable",
                              hint="give its module with blocks=[...] (or --blocks)")
        spec = {"type": typ}
        for k, v in constructor_arguments(b).items():
            spec[k] = _data(v, f"block '{name}', argument '{k}'")
        blocks[name] = spec
    if diagram._ex_in or diagram._ex_out:
        raise EditorError("the diagram exports ports: a scenario file has none",
                          kind="NotEditable")
    wires = [[src.path, dst.path] for dst, src in diagram._driver.items()]
    return {"name": diagram.name or "diagram",
            "parameters": dict(EMPTY_DOCUMENT["parameters"]),
            "blocks": blocks, "wires": wires,
            "simulation": dict(EMPTY_DOCUMENT["simulation"])}
