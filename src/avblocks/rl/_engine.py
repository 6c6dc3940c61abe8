"""The few engine internals the environments step with, imported in one place.

The environments advance a diagram one control step at a time, which the
public run API (``simulate``, ``compile``) does not offer: they use the
engines' pure pieces (outputs, updates, a solver step) directly. Should the
engines move, only this module changes.
"""

from __future__ import annotations

from ..core import rng
from ..core.engine import Engine
from ..core.params import bound_parameters
from ..core.solvers import make_solver


def traced_engine(compiled, dt, jnp, canon):
    """The compiled backend's engine (errors name the block, fixed dtypes)."""
    from ..core.compiled.engine import TracedEngine
    return TracedEngine(compiled, dt, jnp, canon)


def jax():
    """The ``jax`` module (deferred import with avblocks' install hint)."""
    from ..core.compiled import require_jax
    return require_jax()


__all__ = ["Engine", "bound_parameters", "make_solver", "rng", "traced_engine", "jax"]
