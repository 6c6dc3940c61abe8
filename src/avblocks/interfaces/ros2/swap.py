"""Swap a diagram's vehicle model block for a :class:`Robots` block.

Nothing else in the diagram changes: the block handle keeps its name, so
every wire and every logged ``"fleet.pose"`` stays valid. The new block
must have every port of the old one with the same shape (it may have more
outputs: ``fresh``, ``age``).
"""

from __future__ import annotations

import numpy as np

from ...core.errors import ParameterError
from ..flight.swap import replace_block  # noqa: F401  (moved there, shared)
from .robots import Robots

#: Model classes a Robots block of each kind can stand in for.
_FAMILIES = {"Unicycle": "unicycle", "DifferentialDrive": None,
             "SingleIntegrator": "holonomic"}


def _find_model(diagram):
    for name, h in diagram.blocks.items():
        if type(h.block).__name__ in ("Unicycle", "SingleIntegrator"):
            return name
    return None


def robots_like(model, names, **kw):
    """A :class:`Robots` block with the ports of ``model`` (a
    ``vehicles.Unicycle`` or ``vehicles.SingleIntegrator``) for ``names``,
    carrying over its finite command limits. ``kw`` go to Robots."""
    names = names.split(",") if isinstance(names, str) else list(names)
    cls = type(model).__name__
    n = getattr(model, "n", None)
    if n is not None and n != len(names):
        raise ParameterError(f"the model block has {n} vehicles but {len(names)} robot "
                             f"names were given ({names})", param="robots",
                             hint="name one robot per vehicle (e.g. --set agents=...)")
    if cls == "Unicycle":
        for lim in ("v_max", "omega_max"):
            v = np.asarray(getattr(model, lim, np.inf), float)
            if lim not in kw and np.all(np.isfinite(v)):
                kw[lim] = v
        return Robots(names, kind="unicycle", **kw)
    if cls == "SingleIntegrator":
        d = model.output_ports["position"].shape[-1]
        v = np.asarray(getattr(model, "v_max", np.inf), float)
        if "speed_max" not in kw and np.all(np.isfinite(v)):
            kw["speed_max"] = v
        return Robots(names, kind=f"holonomic{d}d", **kw)
    raise ParameterError(f"no robot interface for a {cls} block",
                         param="robots", expected="Unicycle or SingleIntegrator", found=cls)
