"""Vehicle models: one block = N vehicles. Each family is a pure dynamics
function plus a block that wraps it."""

from .unicycle import Unicycle, unicycle_rhs

__all__ = ["Unicycle", "unicycle_rhs"]
