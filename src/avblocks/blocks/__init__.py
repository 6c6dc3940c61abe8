"""Generic blocks: sources, math, continuous and discrete, routing over agents."""

from .action import Action
from .continuous import Integrator
from .discrete import UnitDelay, ZeroOrderHold
from .function import Function
from .math import Gain, Product, Sum
from .nonlinear import DeadZone, RateLimiter, Saturation
from .routing import Concatenate, Demux, Gather, Mux, Select
from .sources import Clock, Constant, Sine, Step

__all__ = [
    "Action", "Constant", "Clock", "Step", "Sine", "Gain", "Sum", "Product", "Integrator",
    "Saturation", "DeadZone", "RateLimiter", "UnitDelay", "ZeroOrderHold",
    "Select", "Gather", "Concatenate", "Mux", "Demux", "Function",
]
