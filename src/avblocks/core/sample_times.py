"""Sample times: when a block's discrete states update and its outputs change.

``CONTINUOUS`` (every solver stage), :class:`Periodic` (``period``,
``offset``: hits at ``offset + k period``, outputs held between hits) and
``INHERITED`` (the block takes its drivers' sample time when the diagram is
built).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .errors import ParameterError


@dataclass(frozen=True)
class Continuous:
    """Sample time of a continuous-time block.

    Its outputs are recomputed at every solver stage. Its discrete states,
    if any (modes such as "current waypoint"), are updated at every major
    step.
    """

    def __repr__(self):
        return "Continuous()"


@dataclass(frozen=True)
class Periodic:
    """Sample time of a discrete block: hits at ``offset + k * period``.

    Outputs are computed at hits and held between them (zero-order hold);
    discrete states are updated at hits.
    """

    period: float
    offset: float = 0.0

    def __post_init__(self):
        if not (math.isfinite(self.period) and self.period > 0):
            raise ParameterError("sample period must be a positive number",
                                 param="period", expected="> 0", found=self.period)
        if not (math.isfinite(self.offset) and 0 <= self.offset < self.period):
            raise ParameterError("sample offset must lie in [0, period)",
                                 param="offset", expected=f"[0, {self.period})",
                                 found=self.offset)


@dataclass(frozen=True)
class Inherited:
    """Sample time taken from the blocks that drive this one, when the
    diagram is built: ``Periodic(p, o)`` if every driver is periodic with the
    same ``(p, o)``, else continuous. For stateless elementwise blocks (gains,
    sums, saturations, routing) placed after a discrete block: they then
    compute once per hit instead of at every solver stage."""

    def __repr__(self):
        return "Inherited()"


CONTINUOUS = Continuous()
INHERITED = Inherited()
