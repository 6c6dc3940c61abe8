"""Generic blocks: sources, math, continuous and discrete, routing over agents."""

from .continuous import Integrator
from .math import Gain, Product, Sum
from .sources import Clock, Constant, Sine, Step

__all__ = ["Constant", "Clock", "Step", "Sine", "Gain", "Sum", "Product", "Integrator"]
