"""The compiled backend (JAX): compile a diagram once, run it many times.

    runner = av.compile(d, t_final=30, dt=0.01, log=[fleet.pose])   # trace + compile
    res = runner(params={"drive.gain": 2.0}, x0={"fleet.pose": p0}, seed=3)
    ens = runner.ensemble(seeds=range(256))                          # vmap, run axis
    g = av.grad(cost, d, wrt=["drive.gain", "fleet.pose@x0"], t_final=20, dt=0.01)
    res = av.simulate(d, 30, dt=0.01, backend="jax", log_every=10)  # same as NumPy

Numeric parameters, initial states and random keys are arguments of one
ahead-of-time compiled ``jit(lax.scan)``; compiled programs are cached by the
diagram's structure. See docs/compiled.md.
"""

from ._jax import jax as require_jax
from .build import compile, grad, simulate_compiled
from .plans import get_plans, load_plans, save_plans, set_plans
from .program import (
    cache_dir,
    cache_info,
    clear_cache,
    clear_persistent_cache,
    enable_persistent_cache,
)
from .runner import Runner

__all__ = ["compile", "grad", "Runner", "simulate_compiled", "cache_info", "clear_cache",
           "enable_persistent_cache", "clear_persistent_cache", "cache_dir", "get_plans",
           "set_plans", "save_plans", "load_plans", "require_jax"]
