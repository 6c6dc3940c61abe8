"""Learning on diagrams: any diagram as a PettingZoo / Gymnasium environment.

>>> from avblocks import rl
>>> env = rl.parallel_env("spread")                 # PettingZoo ParallelEnv
>>> obs, infos = env.reset(seed=0)
>>> sorted(obs)[:2]
['agent_0', 'agent_1']

- :func:`parallel_env` -> PettingZoo ``ParallelEnv`` (one agent per vehicle)
- :func:`gym_env` -> Gymnasium ``Env`` (single-agent diagrams)
- :func:`vector_env` -> Gymnasium ``VectorEnv`` (K copies, one batched call)
- :func:`functional` -> pure ``reset(key, params)`` / ``step(key, state,
  action, params)`` to jit whole training loops over (JAX)

Each takes a diagram with a :class:`~avblocks.blocks.Action` block and the
task's settings (``observe``, ``act``, ``reward``, ``done``, ...; see
:class:`Task`), or the name of a task scenario (``"navigation"``,
``"spread"``, ``"pursuit"``) whose defaults are used, overridden by
keywords. This is an application layer: nothing in the library imports it.
"""

from __future__ import annotations

import importlib
import inspect

from ..core.diagram import CompiledDiagram, Diagram
from ..core.errors import ParameterError, ScenarioError
from .functional import EnvState, FunctionalEnv, Signals, Task

_TASK_KEYS = ("act", "observe", "reward", "done", "reset", "info", "dt", "substeps",
              "max_steps", "solver")


def scenario_task(name, **kw):
    """The :class:`Task` of a task scenario (``avblocks.scenarios.<name>``):
    its ``rl_task(**params)``; ``kw`` are scenario parameters or Task settings."""
    try:
        mod = importlib.import_module(f"avblocks.scenarios.{name}")
    except ImportError:
        mod = None
    if mod is None or not hasattr(mod, "rl_task"):
        raise ScenarioError("not a task scenario (no rl_task)", file=str(name),
                            hint="task scenarios: navigation, spread, pursuit")
    sig = inspect.signature(mod.rl_task)
    sc = {k: v for k, v in kw.items() if k in sig.parameters}
    settings = {k: v for k, v in kw.items() if k not in sig.parameters}
    unknown = [k for k in settings if k not in _TASK_KEYS]
    if unknown:
        raise ParameterError(f"unknown argument(s) {unknown}", param=unknown[0],
                             expected=f"scenario parameters {list(sig.parameters)} or "
                                      f"task settings {list(_TASK_KEYS)}")
    spec = dict(mod.rl_task(**sc))
    spec.update(settings)
    return Task(spec.pop("diagram"), **spec)


def make_task(diagram_or_scenario, **kw):
    """A :class:`Task` from a diagram and settings, a scenario name, or a Task."""
    if isinstance(diagram_or_scenario, Task):
        return diagram_or_scenario.replace(**kw) if kw else diagram_or_scenario
    if isinstance(diagram_or_scenario, str):
        return scenario_task(diagram_or_scenario, **kw)
    if isinstance(diagram_or_scenario, (Diagram, CompiledDiagram)):
        return Task(diagram_or_scenario, **kw)
    raise ParameterError("expected a Diagram, a Task or a task scenario's name",
                         param="diagram_or_scenario",
                         found=type(diagram_or_scenario).__name__)


def functional(diagram_or_scenario, *, backend="jax", **kw):
    """The pure form :class:`FunctionalEnv` (``reset``/``step``, jit/vmap-able)."""
    return FunctionalEnv(make_task(diagram_or_scenario, **kw), backend=backend)


def parallel_env(diagram_or_scenario, *, backend="numpy", params=None, **kw):
    """A PettingZoo ``ParallelEnv``: one agent id (``agent_i``) per row of
    the Action block.

    Parameters
    ----------
    diagram_or_scenario : Diagram, Task or str
        A diagram with an :class:`~avblocks.blocks.Action` block, or a task
        scenario's name (``"navigation"``, ``"spread"``, ``"pursuit"``).
    backend : ``"numpy"`` (default) or ``"jax"``
        The engine each step runs on (JAX: one jitted call per step).
    params : dict, optional
        Numeric parameters ``{"block.param": value}`` for every episode;
        ``reset(options={"params": ...})`` overrides them for one.
    **kw
        :class:`Task` settings (``observe``, ``act``, ``reward``, ``done``,
        ``reset``, ``info``, ``dt``, ``substeps``, ``max_steps``, ``solver``)
        and, with a scenario name, the scenario's parameters.
    """
    from .envs import make_parallel
    return make_parallel(functional(diagram_or_scenario, backend=backend, **kw), params)


def gym_env(diagram_or_scenario, *, backend="numpy", params=None, **kw):
    """A Gymnasium ``Env`` for a single-agent diagram (arguments as
    :func:`parallel_env`)."""
    from .envs import make_gym
    return make_gym(functional(diagram_or_scenario, backend=backend, **kw), params)


def vector_env(diagram_or_scenario, num_envs, *, backend="jax", params=None, **kw):
    """A Gymnasium 1.x ``VectorEnv`` of ``num_envs`` copies, autoreset mode
    ``SAME_STEP`` (see :mod:`avblocks.rl.envs`). JAX: all copies in one
    jitted ``vmap`` call; NumPy: one call on the copies stacked along a
    leading axis (:mod:`avblocks.rl.batched` states the contract)."""
    from .envs import make_vector
    return make_vector(functional(diagram_or_scenario, backend=backend, **kw), num_envs,
                       params)


__all__ = ["Task", "FunctionalEnv", "EnvState", "Signals", "functional", "parallel_env",
           "gym_env", "vector_env", "make_task", "scenario_task"]
