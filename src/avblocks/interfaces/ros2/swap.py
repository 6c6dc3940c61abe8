"""Swap a diagram's vehicle model block for a :class:`Robots` block.

Nothing else in the diagram changes: the block handle keeps its name, so
every wire and every logged ``"fleet.pose"`` stays valid. The new block
must have every port of the old one with the same shape (it may have more
outputs: ``fresh``, ``age``).
"""

from __future__ import annotations

import numpy as np

from ...core.errors import ParameterError, WiringError
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


def replace_block(diagram, name, block):
    """Put ``block`` in place of the block named ``name`` (default: the
    first ``Unicycle``/``SingleIntegrator`` if ``name`` is None) in
    ``diagram``; returns the old block. Ports are checked first."""
    if name is None:
        name = _find_model(diagram)
        if name is None:
            raise WiringError("no vehicle model block to replace",
                              expected="a Unicycle or SingleIntegrator block",
                              hint="name the block to replace")
    if name not in diagram.blocks:
        raise WiringError("no such block to replace", block=name,
                          expected=f"one of {sorted(diagram.blocks)}", found=name)
    handle = diagram[name]
    old = handle.block
    for kind, olds, news in (("input", old.input_ports, block.input_ports),
                             ("output", old.output_ports, block.output_ports)):
        for p, spec in olds.items():
            if p not in news:
                raise WiringError(f"the new block lacks the {kind} port", block=name,
                                  port=p, expected=sorted(olds), found=sorted(news))
            if spec.shape is not None and news[p].shape != spec.shape:
                raise WiringError(f"{kind} port shapes differ", block=name, port=p,
                                  expected=spec.shape, found=news[p].shape)
    extra_in = set(block.input_ports) - set(old.input_ports)
    if extra_in:
        raise WiringError("the new block has inputs the old one had not (they would "
                          "be unconnected)", block=name, found=sorted(extra_in),
                          hint="build it with estop=False, or wire the input afterwards")
    object.__setattr__(handle, "block", block)
    return old
