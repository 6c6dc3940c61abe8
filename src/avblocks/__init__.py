"""avblocks: vectorized building blocks for multi-vehicle and multi-agent systems.

Layers, each importing only from those below it (docs/architecture.md; the
import-linter contracts in pyproject.toml check them): apps (``cli``,
``commands``, the run guard ``_runio``, ``sweep``) > ``scenarios`` > ``viz``,
``interfaces`` > ``controllers``, ``vehicles`` > ``environment`` >
``blocks``, ``utility`` > ``core`` (data, then the NumPy step, the engines,
and the front end ``simulate``/``compile`` that picks one).

>>> import avblocks as av
>>> d = av.Diagram()
"""

from . import analysis, blocks, controllers, core, environment, utility, vehicles
from .analysis import linearize, trim
from .core import (
    Block,
    Continuous,
    Diagram,
    Periodic,
    Port,
    Results,
    Runner,
    Simulator,
    compile,
    grad,
    simulate,
)
from .core.errors import (
                   AlgebraicLoopError,
                   AvError,
                   CompileError,
                   ParameterError,
                   ScenarioError,
                   ShapeError,
                   SimulationError,
                   SimulationWarning,
                   WiringError,
)

__version__ = "0.1.0"

_LAZY = ("viz", "scenarios", "sweep")


def __getattr__(name):
    # viz pulls in Matplotlib: import it (and the scenario loader) on first use
    if name in _LAZY:
        import importlib
        return importlib.import_module(f"avblocks.{name}")
    if name == "edit":      # the editor in a Jupyter cell (extra [editor])
        import importlib
        return importlib.import_module("avblocks.editor").edit
    raise AttributeError(f"module 'avblocks' has no attribute '{name}'")

__all__ = [
    "analysis", "linearize", "trim",
    "blocks", "controllers", "core", "environment", "utility", "vehicles", "viz",
    "scenarios", "sweep", "edit",
    "Block", "Continuous", "Periodic", "Diagram", "Port", "Results", "Simulator",
    "simulate", "compile", "grad", "Runner", "CompileError", "AvError", "ParameterError",
    "WiringError", "ShapeError",
    "AlgebraicLoopError", "SimulationError", "SimulationWarning", "ScenarioError",
    "__version__",
]
