"""Numeric block parameters from the command line and scenario files.

``--set drive.gain=2.0`` and a scenario's ``params: {drive.gain: 2.0}``
name a numeric parameter of a block of the *built* diagram by its dotted
path (``"block.param"``, ``"sub.block.param"`` inside subsystems; see
:meth:`avblocks.core.diagram.CompiledDiagram.parameters`). A key without a
dot is a scenario parameter (``--set agents=300``); ``simulation.<key>``
a simulate setting. The values are validated against the built diagram
(name, shape, bounds) and handed to :func:`avblocks.simulate` as
``params=``, so they are recorded in ``res.meta["params"]``.
"""

from __future__ import annotations

from ..core.errors import AvError, ScenarioError


def is_numeric_key(key) -> bool:
    """True for ``"block.param"`` keys (dotted, not ``simulation.*``)."""
    k = str(key)
    return "." in k and not k.startswith("simulation.")


def split_overrides(overrides) -> tuple[dict, dict]:
    """``(plain, numeric)``: scenario/simulation keys and ``block.param`` keys."""
    plain, numeric = {}, {}
    for k, v in (overrides or {}).items():
        (numeric if is_numeric_key(k) else plain)[k] = v
    return plain, numeric


def resolve(diagram, values, source="<scenario>", entry="--set") -> dict:
    """Validate ``{"block.param": value}`` against ``diagram`` (a Diagram or
    CompiledDiagram); returns ``{path: float array}`` or raises
    :class:`ScenarioError` naming the key, with a "did you mean" hint."""
    if not values:
        return {}
    compiled = diagram.build() if hasattr(diagram, "build") else diagram
    out = {}
    for path, v in values.items():
        where = f"{entry} {path}" if entry == "--set" else f"{entry}.{path}"
        try:
            i, name = compiled.param_index(path)
            out[str(path)] = compiled.blocks[i]._params[name].validate(
                v, compiled.names[i])
        except AvError as e:
            hint = None       # a "did you mean" is part of the message already
            if not getattr(e, "hint", None):
                known = sorted(compiled.parameters())
                hint = f"numeric parameters: {known[:30]}" if known else \
                    "this diagram has no numeric parameters"
            raise ScenarioError(f"bad numeric parameter '{path}': {e}", file=source,
                                entry=where, hint=hint) from None
    return out
