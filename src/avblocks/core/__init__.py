"""The engine: ports, blocks, diagrams, solvers, the simulator and results."""

from . import check, rng
from .block import CONTINUOUS, INHERITED, Block, Continuous, Inherited, Periodic
from .check import check_block
from .compiled import Runner, grad
from .diagram import BlockHandle, CompiledDiagram, Diagram, PortRef
from .errors import (
                     AlgebraicLoopError,
                     AvError,
                     CompileError,
                     ParameterError,
                     ScenarioError,
                     ShapeError,
                     SimulationError,
                     WiringError,
)
from .frontend import compile, simulate
from .ports import Port
from .results import Results
from .simulator import Simulator
from .solvers import RK4, Euler, Scipy, Solver, make_solver

__all__ = [
    "rng", "check", "check_block", "Block", "Continuous", "Periodic", "Inherited",
    "CONTINUOUS", "INHERITED",
    "Diagram", "BlockHandle",
    "PortRef", "CompiledDiagram", "AvError", "ParameterError", "WiringError",
    "ShapeError", "AlgebraicLoopError", "SimulationError", "ScenarioError", "Port",
    "Results", "Simulator", "simulate", "Solver", "Euler", "RK4", "Scipy",
    "make_solver", "compile", "grad", "Runner", "CompileError",
]
