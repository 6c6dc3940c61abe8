"""The static plan of a cell-list search (:class:`CellList`) and what a
search needed (:class:`Need`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ...core.errors import ParameterError


class Need(NamedTuple):
    """What a search needed: compare with the :class:`CellList`'s plan.

    ``capacity``: the most candidates one query point had (points in the
    cells around it; an int array scalar); ``reach``: the largest radius
    asked for (a float array scalar); ``hits``: the most points one query
    point had within the radius (0 when not counted); ``span``: the cells
    of the free-space frame over the cells its integer keys can address
    (above 1: the points are spread too far for the keys; in a traced
    float32 run, beyond about 46,000 cells per axis in 2-D).
    """

    capacity: object
    reach: object
    hits: object = 0
    span: object = 0.0


@dataclass(frozen=True)
class CellList:
    """The static plan of a cell-list search (structural: fixes shapes).

    Parameters
    ----------
    reach : float
        Cell edge lower bound: the largest radius a search may ask for.
        ``inf`` means "no range limit": searches compare every pair
        (O(N^2) work; use only for small N).
    capacity : int or None
        Most candidates per query point (points in the cells around it).
        ``None``: as many as found (NumPy only).
    table : int or None
        Accepted for compatibility; unused (the grid needs no hash table).
    box : tuple of float or None
        Periodic box edge lengths (origin at 0), or ``None`` (free space).
    dim : int
        2 or 3.
    hits : int or None
        Most points within the radius of one query point: the width of
        :func:`within`'s rows. ``None``: as many as found (NumPy only).
    split : int
        Cells per ``reach`` along an axis: a query point looks at ``2 split
        + 1`` cells per axis (finer cells: fewer candidates, more ranges).
    """

    reach: float
    capacity: int | None = None
    table: int | None = None
    box: tuple | None = None
    dim: int = 2
    hits: int | None = None
    split: int = 2

    def __post_init__(self):
        r = float(self.reach)
        if not r > 0:
            raise ParameterError("reach must be > 0", param="reach", expected="> 0",
                                 found=self.reach)
        if self.dim not in (2, 3):
            raise ParameterError("dim must be 2 or 3", param="dim", found=self.dim)
        for name in ("capacity", "hits"):
            v = getattr(self, name)
            if v is not None and int(v) < 1:
                raise ParameterError(f"{name} must be >= 1", param=name, expected=">= 1",
                                     found=v)
        if self.box is not None:
            box = tuple(float(b) for b in np.ravel(self.box))
            if len(box) != self.dim or not all(math.isfinite(b) and b > 0 for b in box):
                raise ParameterError("box must hold one positive length per axis",
                                     param="box", expected=f"{self.dim} lengths > 0",
                                     found=self.box)
            if r > 0.5 * min(box):
                raise ParameterError("reach must be at most half the smallest box edge",
                                     param="reach", expected=f"<= {0.5 * min(box)}",
                                     found=r)
            object.__setattr__(self, "box", box)
        object.__setattr__(self, "reach", r)

    @property
    def brute(self) -> bool:
        """True when every pair is compared (infinite reach)."""
        return not math.isfinite(self.reach)

    def cells_per_axis(self):
        """Cells along each axis of a periodic box (``None`` in free space)."""
        if self.box is None:
            return None
        return tuple(max(1, int(b // (self.reach / self.split))) for b in self.box)

    def cell_edges(self):
        """Edge length of a cell along each axis (``>= reach / split``)."""
        if self.box is None:
            return (self.reach / self.split,) * self.dim
        return tuple(b / c for b, c in zip(self.box, self.cells_per_axis()))

    def exceeded(self, need) -> str | None:
        """A sentence saying what ``need`` exceeds in this plan, or None."""
        cap = int(np.max(np.asarray(need.capacity)))
        hits = int(np.max(np.asarray(need.hits)))
        reach = float(np.max(np.asarray(need.reach)))
        msgs = []
        if self.capacity is not None and not self.brute and cap > self.capacity:
            msgs.append(f"capacity: a point had {cap} candidates around it, "
                        f"capacity is {self.capacity}")
        if self.hits is not None and hits > self.hits:
            msgs.append(f"hits: a point had {hits} others within range, "
                        f"room for {self.hits}")
        if reach > self.reach * (1 + 1e-6):        # float32 rounding of a radius is no overflow
            msgs.append(f"a search asked for radius {reach:g}, the cells were planned "
                        f"for {self.reach:g}")
        span = float(np.max(np.asarray(getattr(need, "span", 0.0))))
        if span > 1.0:
            msgs.append(f"span: the points spread over {span:.3g} times the cells the "
                        "integer cell keys address (run in float64, or use a periodic "
                        "box=)")
        return "; ".join(msgs) or None

    def grown(self, need, headroom=1.5) -> CellList:
        """This plan with room for ``need`` (times ``headroom``)."""
        cap = int(np.max(np.asarray(need.capacity)))
        hits = int(np.max(np.asarray(need.hits)))
        new_cap = self.capacity
        if self.capacity is not None and cap > self.capacity:
            new_cap = int(math.ceil(headroom * cap))
        new_hits = self.hits
        if self.hits is not None and hits > self.hits:
            new_hits = int(math.ceil(headroom * hits))
        if new_cap != self.capacity and new_hits is not None:
            # the hits were counted among candidates cut short to the plan:
            # scale the count by the share that was cut (an estimate; a run
            # that still needs more is re-planned once more)
            est = int(math.ceil(headroom * hits * cap / max(1, self.capacity)))
            new_hits = min(new_cap, max(new_hits, est))
        return CellList(self.reach, new_cap, self.table, self.box, self.dim, new_hits,
                        self.split)
