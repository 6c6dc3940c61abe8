"""Swap a diagram's vehicle model block (or subsystem) for an interface
block with the same ports (shared by the ROS 2 robots and the drones).

Nothing else in the diagram changes: the block handle keeps its name, so
every wire and every logged ``"fleet.position"`` stays valid. The new
block must have every port of the old one with the same shape (it may have
more outputs: ``fresh``, ``age``).
"""

from __future__ import annotations

from ...core.errors import WiringError


def _find_model(diagram):
    for name, h in diagram.blocks.items():
        if type(h.block).__name__ in ("Unicycle", "SingleIntegrator"):
            return name
    return None


def find_flyer(diagram):
    """The name of the block ``fleet`` if there is one, else of the first
    block or subsystem with a ``velocity`` input and a ``position`` output
    of the same (N, 3) shape (a velocity-controlled quadrotor), else None."""
    if "fleet" in diagram.blocks:
        return "fleet"
    for name, h in diagram.blocks.items():
        ins, outs = h.block.input_ports, h.block.output_ports
        if "velocity" in ins and "position" in outs:
            s = ins["velocity"].shape
            if s is not None and len(s) == 2 and s[1] == 3 and outs["position"].shape == s:
                return name
    return None


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
